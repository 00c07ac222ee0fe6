//! Quarter-resolution depth (and scene-flow) maps of a view: STORM's `depth_flows_4/{t}_{cam}.npy`, or the
//! frame's lidar sweep projected into the camera when the export has no such maps.
//!
//! A `depth_flows_4` file has shape `(H/4, W/4, 4)` float32: channel 0 is z-depth in metres (0 = no
//! measurement), channels 1-3 the scene flow of that surface point. Cell `(row, col)` covers the full-resolution
//! pixels `4 row .. 4 row + 4` and `4 col .. 4 col + 4`, so its centre is at continuous coordinates
//! `(4 col + 2, 4 row + 2)`. A lidar map uses the same grid (a return lands in the cell of the pixel it projects
//! into; the nearest return of a cell wins) and has no flow: the exports' lidar flow columns are not in the
//! camera-relative units the motion supervision needs.
//!
//! Who writes the maps: STORM's Waymo export, the synthetic scenes (exact surface velocities), and the converters
//! with `--depth-flows boxes` (`dggt_convert::depth_flows`: lidar returns binned as above, flow from the tracked
//! box each return lies in, zero outside boxes).
//!
//! Axes: [`Scene::depth_map`] gives the flow along the log world's axes (metres per second), the axes the
//! converters and the generator write. STORM's maps carry it along the axes of the frame's vehicle and are
//! turned on reading ([`FlowOrigin::Export`]).

use std::path::Path;

use dggt_geom::glam::DVec3;
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics};

use crate::error::{DataError, Result};
use crate::layout::ExportLayout;
use crate::lidar::project_to_depth;
use crate::npy::read_npy_f32;
use crate::scene::Scene;

/// Downsampling factor of the maps.
pub const DEPTH_FLOW_STRIDE: u32 = 4;

/// Where a scene's depth supervision comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthSource {
    /// The export's `depth_flows_4` maps (depth and scene flow).
    DepthFlows4,
    /// The export's lidar sweeps projected into each view (depth only).
    Lidar,
}

/// Where a scene's scene flow (the `depth_flows_4` maps' channels 1-3) comes from, as the export records it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlowOrigin {
    /// No `depth_flows_4` maps: no scene flow (lidar sweeps carry none).
    Absent,
    /// The exact surface velocities of a generated scene (`dggt synth`, `synth.json`).
    Synthetic,
    /// Lidar returns moved with the tracked 3D box they lie in, zero outside boxes (`dggt convert --depth-flows
    /// boxes`).
    TrackedBoxes,
    /// Maps the export came with from elsewhere (STORM's Waymo export): the flow as that export computed it,
    /// along the axes of the frame's vehicle (turned into the log world's when read, [`Scene::depth_map`]).
    Export,
}

impl FlowOrigin {
    /// What `dggt inspect` and `dggt eval` call it.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Absent => "none",
            Self::Synthetic => "exact, from the generated scene's trajectories",
            Self::TrackedBoxes => "tracked 3D boxes (dggt convert --depth-flows boxes)",
            Self::Export => "the export's own depth_flows_4 (not written by dggt)",
        }
    }
}

/// What `depth_flows_4/origin.json` holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
struct FlowRecord {
    scene_flow: FlowOrigin,
}

/// Records beside a scene's maps where their flow comes from (what [`Scene::flow_origin`] reads).
pub fn write_flow_origin(layout: &ExportLayout, origin: FlowOrigin) -> Result<()> {
    let path = layout.depth_flow_origin();
    let bytes = serde_json::to_vec_pretty(&FlowRecord { scene_flow: origin })
        .map_err(|e| DataError::malformed(&path, "a serialisable flow record", e.to_string()))?;
    crate::io::write_atomically(&path, &bytes)
}

/// One quarter-resolution depth map, with scene flow where the source has it.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFlowMap {
    /// Size of the quarter-resolution grid.
    pub size: ImageSize,
    /// Row-major z-depth, 0 where unknown.
    pub depth: Vec<f32>,
    /// Row-major scene flow (the log world's axes, units per second); `None` for lidar maps.
    pub flow: Option<Vec<[f32; 3]>>,
}

/// The quarter-resolution grid of a full-resolution image.
fn grid_size(image_size: ImageSize) -> ImageSize {
    ImageSize { width: image_size.width / DEPTH_FLOW_STRIDE, height: image_size.height / DEPTH_FLOW_STRIDE }
}

impl DepthFlowMap {
    /// Reads a map and checks it against the full-resolution image size it belongs to.
    pub fn read(path: &Path, image_size: ImageSize) -> Result<Self> {
        let array = read_npy_f32(path)?;
        let grid = grid_size(image_size);
        let expected = [grid.height as usize, grid.width as usize, 4];
        if array.shape != expected {
            return Err(DataError::malformed(
                path,
                format!("shape {expected:?} (a quarter of the {image_size} image, 4 channels)"),
                format!("{:?}", array.shape),
            ));
        }
        if let Some(i) = array.data.iter().position(|v| !v.is_finite()) {
            return Err(DataError::malformed(path, "finite values", format!("a non-finite value at index {i}")));
        }
        let depth = array.data.chunks_exact(4).map(|c| c[0]).collect();
        let flow = array.data.chunks_exact(4).map(|c| [c[1], c[2], c[3]]).collect();
        Ok(Self { size: grid, depth, flow: Some(flow) })
    }

    /// Bins world points seen by a camera into the grid of its `image_size` image: a point projecting to the
    /// continuous pixel `(u, v)` lands in cell `(floor(v / 4), floor(u / 4))`; the nearest point of a cell wins.
    pub fn from_points(
        points_in_world: &[DVec3],
        camera_from_world: &CameraFromWorld,
        intrinsics: &PinholeIntrinsics,
        image_size: ImageSize,
    ) -> Self {
        let scale = 1.0 / DEPTH_FLOW_STRIDE as f64;
        let grid = grid_size(image_size);
        let depth = project_to_depth(points_in_world, camera_from_world, &intrinsics.scaled(scale, scale), grid);
        Self { size: grid, depth, flow: None }
    }
}

impl Scene {
    /// Where this scene's depth supervision comes from: `depth_flows_4` when every view has a map, else lidar
    /// when every frame has a sweep; `None` when neither.
    pub fn depth_source(&self) -> Option<DepthSource> {
        if self.all_views_have(|v| v.depth_flow.is_some()) {
            Some(DepthSource::DepthFlows4)
        } else if !self.lidar.is_empty() && self.lidar.iter().all(Option::is_some) {
            Some(DepthSource::Lidar)
        } else {
            None
        }
    }

    /// Where this scene's scene flow comes from: the record beside the maps (`depth_flows_4/origin.json`, which
    /// the converters write), else a generated scene's exact flow (`synth.json`), else the export's own maps;
    /// [`FlowOrigin::Absent`] without `depth_flows_4` maps for every view.
    pub fn flow_origin(&self) -> Result<FlowOrigin> {
        if self.depth_source() != Some(DepthSource::DepthFlows4) {
            return Ok(FlowOrigin::Absent);
        }
        self.maps_origin()
    }

    /// Who wrote the scene's `depth_flows_4` maps, whether or not every view has one: the record, else a
    /// generated scene's description, else the export.
    fn maps_origin(&self) -> Result<FlowOrigin> {
        let layout = ExportLayout::new(&self.root);
        let record = layout.depth_flow_origin();
        match std::fs::read(&record) {
            Ok(bytes) => serde_json::from_slice::<FlowRecord>(&bytes)
                .map(|r| r.scene_flow)
                .map_err(|e| DataError::malformed(&record, "`{\"scene_flow\": ...}`", e.to_string())),
            Err(_) if layout.synth_description().is_file() => Ok(FlowOrigin::Synthetic),
            Err(_) => Ok(FlowOrigin::Export),
        }
    }

    /// The depth map of the view at frame position `frame` and camera position `camera`: its `depth_flows_4`
    /// file when it has one (its flow along the log world's axes, whatever the origin), else the frame's lidar
    /// sweep projected into the camera; `None` when neither.
    pub fn depth_map(&self, frame: usize, camera: usize) -> Result<Option<DepthFlowMap>> {
        let view = self.view(frame, camera);
        let size = self.cameras[camera].size;
        if let Some(path) = &view.files.depth_flow {
            let map = DepthFlowMap::read(path, size)?;
            return match self.maps_origin()? {
                FlowOrigin::Export => self.turned_from_vehicle_axes(map, frame, path).map(Some),
                _ => Ok(Some(map)),
            };
        }
        let Some(Some(sweep)) = self.lidar.get(frame) else { return Ok(None) };
        let points = sweep.read_in_world()?;
        let camera_from_world = view.world_from_camera.inverse();
        Ok(Some(DepthFlowMap::from_points(&points, &camera_from_world, &self.cameras[camera].intrinsics, size)))
    }

    /// `map` (read from `path`, of frame position `frame`) with its flow turned from the axes of the frame's
    /// vehicle into the log world's. STORM's Waymo export writes Waymo's per-point velocities as they come,
    /// along the vehicle frame of `frame.pose` (docs/DATA.md); the converters here and the generator write the
    /// log world's axes. Speeds are unchanged: which cells move does not depend on the axes.
    fn turned_from_vehicle_axes(&self, mut map: DepthFlowMap, frame: usize, path: &Path) -> Result<DepthFlowMap> {
        let Some(world_from_ego) = self.frames[frame].world_from_ego else {
            return Err(DataError::malformed(
                path,
                "an ego pose for its frame (its flow is along the vehicle's axes)",
                "a scene without ego poses",
            ));
        };
        let log_from_ego = (self.world_from_log.inverse() * world_from_ego).rotation_matrix();
        if let Some(flow) = &mut map.flow {
            for velocity in flow.iter_mut() {
                let turned = log_from_ego * DVec3::from(velocity.map(f64::from));
                *velocity = turned.to_array().map(|v| v as f32);
            }
        }
        Ok(map)
    }
}
