//! `depth_flows_4/{t:03}_{cam}.npy` from a frame's lidar returns and their box flow ([`crate::box_flow`]), so
//! that motion can be scored on converted real logs.
//!
//! The file is what [`dggt_data::DepthFlowMap::read`] reads: float32 of shape `(H/4, W/4, 4)` (integer
//! division), channel 0 the z-depth in metres along the camera's optical axis (0: no return), channels 1-3 the
//! scene flow of that return in the **log world's axes** (the world of `ego_pose/` and `instances/`; nuScenes:
//! the global frame of `lidar_pose/`), in **metres per second**, from the frame to its next frame (the previous
//! one at the last frame; see [`crate::box_flow`]). A return lands in the cell of the pixel it projects into with
//! the export's pinhole intrinsics (lens distortion ignored, as the reader does): cell `(floor(v / 4),
//! floor(u / 4))`; the nearest return of a cell wins, and the cell takes its depth and flow.
//!
//! A frame without lidar returns (a Waymo record without range images) gets empty maps when the log has lidar
//! elsewhere, and no log without any lidar gets a `depth_flows_4/` folder (the reader requires a map for every
//! view once the folder exists).

use std::path::{Path, PathBuf};

use dggt_data::depth_flow::{DEPTH_FLOW_STRIDE, FlowOrigin, write_flow_origin};
use dggt_data::{ExportLayout, npy};
use dggt_geom::frames::Frame;
use dggt_geom::glam::DVec3;
use dggt_geom::{Camera, Ego, ImageSize, LogWorld, PinholeIntrinsics, Rigid};

use crate::box_flow::{FrameBoxes, FrameFlow, WorldBox};
use crate::boxes::AnnotatedBox;
use crate::camera::EgoCamera;
use crate::error::{ConvertError, Result};

/// Whether a converter writes `depth_flows_4/`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthFlows {
    /// No `depth_flows_4/` (the trainer and evaluator then project the lidar sweeps, which carry no flow).
    #[default]
    None,
    /// Lidar depth with scene flow from the tracked boxes.
    FromBoxes,
}

impl DepthFlows {
    /// The name a done marker records.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::FromBoxes => "boxes",
        }
    }
}

/// Channels of a map cell: z-depth, then flow x, y, z.
const CHANNELS: usize = 4;

/// One exported camera as the maps are projected into it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapView {
    /// Export camera id.
    pub camera: usize,
    /// World points into OpenCV camera axes, at the frame's time.
    pub camera_from_world: Rigid<Camera, LogWorld>,
    pub intrinsics: PinholeIntrinsics,
    /// Full-resolution image size.
    pub size: ImageSize,
}

impl MapView {
    /// A camera fixed on the ego, at the frame whose ego pose is `world_from_ego`.
    pub fn on_ego(camera: usize, projection: &EgoCamera, world_from_ego: &Rigid<LogWorld, Ego>) -> Self {
        Self {
            camera,
            camera_from_world: projection.camera_from_ego * world_from_ego.inverse(),
            intrinsics: projection.intrinsics,
            size: projection.size,
        }
    }
}

/// The quarter-resolution grid of a full-resolution image.
fn grid(size: ImageSize) -> (usize, usize) {
    ((size.height / DEPTH_FLOW_STRIDE) as usize, (size.width / DEPTH_FLOW_STRIDE) as usize)
}

/// The `(H/4, W/4, 4)` values of one view: `points_in_world[i]` moving at `velocities[i]` (m/s), binned into the
/// grid of the `size` image; the nearest point of a cell wins.
pub fn depth_flow_cells<W: Frame>(
    points_in_world: &[DVec3],
    velocities: &[DVec3],
    camera_from_world: &Rigid<Camera, W>,
    intrinsics: &PinholeIntrinsics,
    size: ImageSize,
) -> Vec<f32> {
    let (rows, cols) = grid(size);
    let scale = 1.0 / DEPTH_FLOW_STRIDE as f64;
    let quarter = intrinsics.scaled(scale, scale);
    let mut cells = vec![0f32; rows * cols * CHANNELS];
    for (&p, velocity) in points_in_world.iter().zip(velocities) {
        let in_camera = camera_from_world.transform_point(p);
        let Some(pixel) = quarter.project(in_camera) else { continue };
        if pixel.x < 0.0 || pixel.y < 0.0 || pixel.x >= cols as f64 || pixel.y >= rows as f64 {
            continue;
        }
        let cell = &mut cells[(pixel.y as usize * cols + pixel.x as usize) * CHANNELS..][..CHANNELS];
        let z = in_camera.z as f32;
        if cell[0] == 0.0 || z < cell[0] {
            let v = velocity.as_vec3();
            cell.copy_from_slice(&[z, v.x, v.y, v.z]);
        }
    }
    cells
}

/// One frame as the maps need it.
#[derive(Debug, Clone)]
pub struct FrameSample {
    pub frame: usize,
    /// The frame's lidar returns in the log's world; `None` when the frame has no lidar.
    pub points_in_world: Option<Vec<DVec3>>,
    /// The frame's boxes in the log's world and its time.
    pub boxes: FrameBoxes,
    pub views: Vec<MapView>,
}

impl FrameSample {
    /// A frame whose lidar returns and boxes are in its ego frame, posed in the log's world by `world_from_ego`
    /// (Waymo, Argoverse 2); `points_in_ego` is `None` for a frame without lidar.
    pub fn in_ego(
        frame: usize,
        time_s: f64,
        world_from_ego: &Rigid<LogWorld, Ego>,
        points_in_ego: Option<impl Iterator<Item = DVec3>>,
        boxes: &[AnnotatedBox],
        views: Vec<MapView>,
    ) -> Self {
        Self {
            frame,
            points_in_world: points_in_ego.map(|points| points.map(|p| world_from_ego.transform_point(p)).collect()),
            boxes: FrameBoxes { time_s, boxes: boxes.iter().map(|b| WorldBox::of(b, world_from_ego)).collect() },
            views,
        }
    }
}

/// Writes the maps of a log's frames as they come: a frame is written once its next frame is known (the flow
/// looks ahead), the last one by [`Self::finish`].
pub struct DepthFlowWriter<'a> {
    layout: &'a ExportLayout,
    /// The file the boxes come from, for errors.
    source: PathBuf,
    previous: Option<FrameBoxes>,
    pending: Option<FrameSample>,
    /// Frames without lidar: their views get empty maps if any frame has lidar.
    without_lidar: Vec<(usize, Vec<MapView>)>,
    written: usize,
}

impl<'a> DepthFlowWriter<'a> {
    /// A writer into `layout`; `source` names the file the boxes are read from.
    pub fn new(layout: &'a ExportLayout, source: &Path) -> Self {
        Self { layout, source: source.to_owned(), previous: None, pending: None, without_lidar: Vec::new(), written: 0 }
    }

    /// Adds the next frame (frames come in order), writing the one before it.
    pub fn push(&mut self, sample: FrameSample) -> Result<()> {
        if let Some(pending) = self.pending.take() {
            self.write(&pending, Some(&sample.boxes))?;
            self.previous = Some(pending.boxes);
        }
        self.pending = Some(sample);
        Ok(())
    }

    /// Writes the last frame and, when any frame had lidar, empty maps for the frames without and the record
    /// of where the flow comes from (`depth_flows_4/origin.json`: tracked boxes); returns how many frames got
    /// maps from lidar.
    pub fn finish(mut self) -> Result<usize> {
        if let Some(pending) = self.pending.take() {
            self.write(&pending, None)?;
        }
        if self.written > 0 {
            for (frame, views) in &self.without_lidar {
                for view in views {
                    write_cells(
                        self.layout,
                        *frame,
                        view,
                        &depth_flow_cells(&[], &[], &view.camera_from_world, &view.intrinsics, view.size),
                    )?;
                }
            }
            write_flow_origin(self.layout, FlowOrigin::TrackedBoxes)?;
        }
        Ok(self.written)
    }

    fn write(&mut self, sample: &FrameSample, next: Option<&FrameBoxes>) -> Result<()> {
        let Some(points) = &sample.points_in_world else {
            self.without_lidar.push((sample.frame, sample.views.clone()));
            return Ok(());
        };
        let flow = FrameFlow::new(&sample.boxes, next, self.previous.as_ref())
            .map_err(|source| ConvertError::BoxFlow { path: self.source.clone(), frame: sample.frame, source })?;
        let velocities: Vec<DVec3> = points.iter().map(|&p| flow.velocity(p)).collect();
        for view in &sample.views {
            let cells = depth_flow_cells(points, &velocities, &view.camera_from_world, &view.intrinsics, view.size);
            write_cells(self.layout, sample.frame, view, &cells)?;
        }
        self.written += 1;
        Ok(())
    }
}

fn write_cells(layout: &ExportLayout, frame: usize, view: &MapView, cells: &[f32]) -> Result<()> {
    let (rows, cols) = grid(view.size);
    Ok(npy::write_npy_f32(&layout.depth_flow(frame, view.camera), &[rows, cols, CHANNELS], cells)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_data::DepthFlowMap;
    use dggt_geom::World;

    fn forward_camera() -> (Rigid<Camera, World>, PinholeIntrinsics, ImageSize) {
        let ego_from_camera = dggt_geom::axes::ego_from_opencv_camera(&Rigid::IDENTITY);
        let camera_from_world: Rigid<Camera, World> = ego_from_camera.inverse().relabel();
        (camera_from_world, PinholeIntrinsics::new(100.0, 100.0, 50.0, 40.0).unwrap(), ImageSize::new(102, 81).unwrap())
    }

    #[test]
    fn the_depth_channel_bins_points_as_the_reader_bins_a_lidar_sweep() {
        let (camera_from_world, intrinsics, size) = forward_camera();
        // A fan of points at varying depths, several per cell, some outside the image and behind the camera.
        let points: Vec<DVec3> = (0..4000)
            .map(|i| {
                let i = i as f64;
                DVec3::new(2.0 + (i * 0.37) % 20.0 - 3.0, (i * 0.13) % 8.0 - 4.0, (i * 0.07) % 5.0 - 2.5)
            })
            .collect();
        // A velocity that depends on the depth alone, so that any point at a cell's depth tells its flow.
        let velocities: Vec<DVec3> = points.iter().map(|p| DVec3::new(p.x, -2.0 * p.x, 1.0)).collect();
        let cells = depth_flow_cells(&points, &velocities, &camera_from_world, &intrinsics, size);
        let reader = DepthFlowMap::from_points(&points, &camera_from_world, &intrinsics, size);
        assert_eq!((reader.size.width, reader.size.height), (25, 20));
        let depth: Vec<f32> = cells.chunks_exact(4).map(|c| c[0]).collect();
        assert_eq!(depth, reader.depth);
        assert!(depth.iter().filter(|&&d| d > 0.0).count() > 100);
        // Each filled cell carries the flow of the point whose depth it holds.
        for cell in cells.chunks_exact(4).filter(|c| c[0] > 0.0) {
            let winner = points
                .iter()
                .zip(&velocities)
                .find(|(p, _)| camera_from_world.transform_point(**p).z as f32 == cell[0])
                .expect("a point at the cell's depth");
            assert_eq!(&cell[1..], &winner.1.as_vec3().to_array());
        }
    }
}
