//! One nuScenes scene (a row of the `scene` table) into one scene folder of drivestudio's nuScenes export
//! ([`dggt_data::ExportVariant::NuScenes`]). Frame `t` is the scene's `t`-th sample (2 Hz, drivestudio's default),
//! or with [`FrameRate::Interpolated`] the `t`-th of the key frames and the frames between them ([`super::frames`]).
//!
//! | path | content |
//! |---|---|
//! | `images/{t:03}_{cam}.jpg` | a copy of the camera's JPEG (the key frame's, or the nearest in time) |
//! | `intrinsics/{cam}.txt` | `K00 K11 K02 K12 0 0 0 0 0`, one per line (the images are undistorted) |
//! | `extrinsics/{t:03}_{cam}.txt` | 4x4 camera -> global, OpenCV axes: `global_from_ego(the camera's own ego_pose) · ego_from_camera` |
//! | `lidar_pose/{t:03}.txt` | 4x4 LIDAR_TOP -> global: `global_from_ego(the lidar's ego_pose) · ego_from_lidar` |
//! | `lidar/{t:03}.bin` | N x 4 float32 `x y z intensity` in the **LIDAR_TOP frame** (x right, y forward, z up) |
//! | `timestamps.txt` | `t seconds` per frame (its target time), since the first sample |
//! | `dynamic_masks/{all,human,vehicle}/{t:03}_{cam}.png` | as [`DynamicMaskStyle`] says: by default the outlines of the objects whose tracks move, each box placed at the camera's own time ([`Tracks::box_at`]); with [`DynamicMaskStyle::Drivestudio`] every annotated box of the class ([`MaskRule::EveryBox`]) at the frame's time, as rectangles; either moved from global into the camera's ego frame |
//! | `instances/` | the annotations' instances ([`crate::instances`]); `obj_to_world` in the global frame |
//! | `sky_masks/` | with [`SkyMasks::Lidar`] only ([`crate::sky`]) |
//! | `depth_flows_4/{t:03}_{cam}.npy` | with [`DepthFlows::FromBoxes`] only ([`crate::depth_flows`]): the frame's LIDAR_TOP points, flow from its boxes (annotated, or interpolated between key frames) of the same instance at `t + 1` (or `t - 1`), times the frames' target times; each camera projected with its own per-frame pose |
//! | [`DONE_MARKER`](crate::marker::DONE_MARKER) | written last |
//!
//! Frames: global (the log's world, [`LogWorld`]), ego (vehicle, forward-left-up), [`Sweep`] (LIDAR_TOP),
//! [`Camera`] (OpenCV axes). Export camera ids: 0 CAM_FRONT, 1 CAM_FRONT_LEFT, 2 CAM_FRONT_RIGHT, 3 CAM_BACK_LEFT,
//! 4 CAM_BACK_RIGHT, 5 CAM_BACK.

use std::path::Path;

use dggt_data::{ExportLayout, ExportVariant, io, text};
use dggt_geom::glam::DVec3;
use dggt_geom::{Camera, Ego, ImageSize, LogWorld, PinholeIntrinsics, Rigid, Sweep};

use super::annotations::GlobalBox;
use super::frames::{FrameRate, PlannedFrame, plan};
use super::tables::{SampleDataRow, Tables};
use crate::box_flow::{FrameBoxes, WorldBox};
use crate::boxes::AnnotatedBox;
use crate::camera::{Distortion, EgoCamera};
use crate::depth_flows::{DepthFlowWriter, DepthFlows, FrameSample, MapView};
use crate::error::{ConvertError, Result};
use crate::instance_masks;
use crate::instances::InstanceLog;
use crate::marker::{DoneMarker, write_done};
use crate::masks::{DynamicMaskStyle, DynamicMasks, MaskRule};
use crate::sky::{self, SkyMasks};
use crate::tracks::Tracks;

/// What a converted scene holds.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSummary {
    pub name: String,
    pub frames: usize,
    pub instances: usize,
}

/// A sensor reading with its poses: `global_from_ego` at the reading's own time, and the sensor's mounting.
struct Reading<'a, S> {
    data: &'a SampleDataRow,
    global_from_ego: Rigid<LogWorld, Ego>,
    ego_from_sensor: Rigid<Ego, S>,
}

impl<'a, S: dggt_geom::frames::Frame> Reading<'a, S> {
    fn of(tables: &'a Tables, frame: &PlannedFrame<'a>, channel: &str) -> Result<Self> {
        let data = frame.readings[channel];
        let referrer = format!("sample_data `{}`", data.token);
        let pose = tables.ego_pose.get(&data.ego_pose_token, &referrer)?;
        let calibration = tables.calibrated_sensor.get(&data.calibrated_sensor_token, &referrer)?;
        Ok(Self {
            data,
            global_from_ego: tables.ego_pose.rigid(&pose.token, pose.rotation, pose.translation)?,
            ego_from_sensor: tables.calibrated_sensor.rigid(
                &calibration.token,
                calibration.rotation,
                calibration.translation,
            )?,
        })
    }

    fn global_from_sensor(&self) -> Rigid<LogWorld, S> {
        self.global_from_ego * self.ego_from_sensor
    }

    /// The file the row points at, read whole.
    fn bytes(&self, tables: &Tables) -> Result<Vec<u8>> {
        let path = tables.file_of(self.data)?;
        std::fs::read(&path).map_err(|e| {
            ConvertError::io(&path, std::io::Error::new(e.kind(), format!("sample_data `{}`: {e}", self.data.token)))
        })
    }
}

/// A camera's pinhole intrinsics from its `calibrated_sensor` row, and its image size from the `sample_data` row.
fn camera_projection(tables: &Tables, reading: &Reading<Camera>) -> Result<EgoCamera> {
    let calibration = tables.calibrated_sensor.get(&reading.data.calibrated_sensor_token, "a camera")?;
    let k = &calibration.camera_intrinsic;
    let invalid = |found: String| {
        tables.calibrated_sensor.error(&calibration.token, "a 3x3 camera_intrinsic with positive focal lengths", found)
    };
    if k.len() != 3 || k.iter().any(|row| row.len() != 3) {
        return Err(invalid(format!("{k:?}")));
    }
    let intrinsics = PinholeIntrinsics::new(k[0][0], k[1][1], k[0][2], k[1][2]).map_err(|e| invalid(e.to_string()))?;
    let size = ImageSize::new(reading.data.width, reading.data.height).map_err(|e| {
        tables.sample_data.error(&reading.data.token, "a positive image width and height", e.to_string())
    })?;
    Ok(EgoCamera {
        intrinsics,
        distortion: Distortion::default(),
        camera_from_ego: reading.ego_from_sensor.inverse(),
        size,
    })
}

/// A `.pcd.bin` sweep: N x 5 float32 (x, y, z, intensity, ring) in the lidar frame.
fn sweep_points(tables: &Tables, reading: &Reading<Sweep>) -> Result<Vec<[f32; 5]>> {
    let bytes = reading.bytes(tables)?;
    if bytes.len() % 20 != 0 {
        return Err(ConvertError::Table {
            path: tables.file_of(reading.data)?,
            expected: format!("sample_data `{}`: N x 5 float32 (a multiple of 20 bytes)", reading.data.token),
            found: format!("{} bytes", bytes.len()),
        });
    }
    Ok(bytes
        .chunks_exact(20)
        .map(|row| std::array::from_fn(|i| f32::from_le_bytes(row[i * 4..i * 4 + 4].try_into().expect("4 bytes"))))
        .collect())
}

/// What a written frame hands on to `instances/` and the depth-flow maps.
struct WrittenFrame {
    /// The boxes in the lidar's ego frame.
    boxes_in_ego: Vec<AnnotatedBox>,
    /// That ego's global pose.
    global_from_ego: Rigid<LogWorld, Ego>,
    /// The sweep's points in the global frame.
    points_in_global: Vec<DVec3>,
    /// The cameras with their own poses at this frame.
    views: Vec<MapView>,
}

/// The boxes a camera's dynamic masks draw, in its ego frame at its own time: with moving outlines, each box moved
/// along its track to the camera's time (`time_s`) and given its track's speed there; drivestudio's, the frame's
/// boxes as they are.
fn view_boxes(
    frame: &PlannedFrame,
    tracks: &Tracks,
    time_s: f64,
    global_from_ego: &Rigid<LogWorld, Ego>,
    style: DynamicMaskStyle,
) -> Vec<AnnotatedBox> {
    let in_ego = frame.boxes.iter().map(|b| b.in_ego(global_from_ego));
    match style {
        DynamicMaskStyle::MovingOutlines { .. } => {
            in_ego.map(|object| tracks.at_view(object, time_s, global_from_ego)).collect()
        }
        DynamicMaskStyle::Drivestudio => in_ego.collect(),
    }
}

/// Writes frame `t`; `tracks` and `first_us` place boxes at each camera's time.
fn write_frame<'a>(
    tables: &'a Tables,
    frame: &PlannedFrame<'a>,
    t: usize,
    (tracks, first_us): (&Tracks, i64),
    options: &NuScenesOptions,
    layout: &ExportLayout,
    instances: &mut InstanceLog,
) -> Result<WrittenFrame> {
    let lidar = Reading::<Sweep>::of(tables, frame, LIDAR)?;
    let points = sweep_points(tables, &lidar)?;
    let rows: Vec<u8> = points.iter().flat_map(|p| p[..4].iter().flat_map(|v| v.to_le_bytes())).collect();
    io::write_atomically(&layout.lidar(t), &rows)?;
    let global_from_lidar = lidar.global_from_sensor();
    text::write_rows(&layout.lidar_pose(t), &global_from_lidar.to_rows())?;
    let boxes_in_ego: Vec<AnnotatedBox> = frame.boxes.iter().map(|b| b.in_ego(&lidar.global_from_ego)).collect();
    instances.register(&boxes_in_ego);
    let names = ExportVariant::NuScenes.camera_names();
    let mut views = Vec::new();
    for &id in &options.cameras {
        let reading = Reading::<Camera>::of(tables, frame, names[id])?;
        let camera = camera_projection(tables, &reading)?;
        io::write_atomically(&layout.image(t, id), &reading.bytes(tables)?)?;
        text::write_rows(&layout.extrinsics_at(t, id), &reading.global_from_sensor().to_rows())?;
        let time_s = (reading.data.timestamp - first_us) as f64 * 1e-6;
        let in_ego = view_boxes(frame, tracks, time_s, &reading.global_from_ego, options.dynamic_masks);
        let (rule, shape) = options.dynamic_masks.rule_and_shape(MaskRule::EveryBox);
        DynamicMasks::draw(&camera, &in_ego, rule, shape).write(layout, t, id)?;
        instance_masks::write(layout, (t, id), &camera, &in_ego, instances)?;
        if options.sky_masks == SkyMasks::Lidar {
            let ego_from_lidar = reading.global_from_ego.inverse() * global_from_lidar;
            let in_ego = points
                .iter()
                .map(|p| ego_from_lidar.transform_point(DVec3::new(p[0].into(), p[1].into(), p[2].into())));
            let top_beam = sky::TopBeam::Known(ego_from_lidar.inverse());
            sky::write_lidar_sky_mask(layout, t, id, &sky::lidar_sky_mask(&camera, in_ego, top_beam))?;
        }
        if t == 0 {
            let k = camera.intrinsics;
            text::write_rows(&layout.intrinsics(id), &[k.fx, k.fy, k.cx, k.cy, 0.0, 0.0, 0.0, 0.0, 0.0].map(|v| [v]))?;
        }
        let camera_from_world = reading.global_from_sensor().inverse();
        views.push(MapView { camera: id, camera_from_world, intrinsics: camera.intrinsics, size: camera.size });
    }
    Ok(WrittenFrame {
        boxes_in_ego,
        global_from_ego: lidar.global_from_ego,
        points_in_global: points
            .iter()
            .map(|p| global_from_lidar.transform_point(DVec3::new(p[0].into(), p[1].into(), p[2].into())))
            .collect(),
        views,
    })
}

/// The tracks of the planned frames' boxes, times in seconds since `first_us`.
fn frame_tracks(frames: &[PlannedFrame], first_us: i64) -> Tracks {
    let frames: Vec<(f64, Vec<WorldBox>)> = frames
        .iter()
        .map(|f| ((f.time_us - first_us) as f64 * 1e-6, f.boxes.iter().map(GlobalBox::world_box).collect()))
        .collect();
    Tracks::new(frames.iter().map(|(t, boxes)| (*t, boxes.as_slice())))
}

/// The lidar channel exported.
const LIDAR: &str = "LIDAR_TOP";

/// What to export of each scene.
#[derive(Debug, Clone, PartialEq)]
pub struct NuScenesOptions {
    /// Export camera ids (0 CAM_FRONT .. 5 CAM_BACK).
    pub cameras: Vec<usize>,
    pub sky_masks: SkyMasks,
    pub depth_flows: DepthFlows,
    pub dynamic_masks: DynamicMaskStyle,
    pub rate: FrameRate,
}

/// Converts scene number `index` of `tables` into the scene folder `scene`; `progress` gets the number of frames
/// written so far.
pub fn convert_scene(
    tables: &Tables,
    index: usize,
    scene: &Path,
    options: &NuScenesOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<SceneSummary> {
    let layout = ExportLayout::new(scene);
    let names = ExportVariant::NuScenes.camera_names();
    if let Some(unknown) = options.cameras.iter().find(|&&id| id >= names.len()) {
        return Err(ConvertError::Table {
            path: tables.sensor.path.clone(),
            expected: format!("a nuScenes export camera id 0..={} ({})", names.len() - 1, names.join(", ")),
            found: format!("camera {unknown}"),
        });
    }
    let (scene_row, samples) = tables.scene_samples(index)?;
    let log = tables.log.get(&scene_row.log_token, &format!("scene `{}`", scene_row.token))?;
    let channels: Vec<&str> = std::iter::once(LIDAR).chain(options.cameras.iter().map(|&id| names[id])).collect();
    let frames = plan(tables, &samples, &channels, options.rate)?;
    let mut instances = InstanceLog::default();
    let mut depth_flows = (options.depth_flows == DepthFlows::FromBoxes)
        .then(|| DepthFlowWriter::new(&layout, &tables.sample_annotation.path));
    let first = frames[0].time_us;
    let tracks = frame_tracks(&frames, first);
    for (t, frame) in frames.iter().enumerate() {
        progress(t as u64);
        let written = write_frame(tables, frame, t, (&tracks, first), options, &layout, &mut instances)?;
        if let Some(writer) = &mut depth_flows {
            let boxes = frame.boxes.iter().map(GlobalBox::world_box);
            writer.push(FrameSample {
                frame: t,
                points_in_world: Some(written.points_in_global),
                boxes: FrameBoxes { time_s: (frame.time_us - first) as f64 * 1e-6, boxes: boxes.collect() },
                views: written.views,
            })?;
        }
        instances.add_frame(t, &written.global_from_ego, &written.boxes_in_ego);
    }
    if let Some(writer) = depth_flows {
        writer.finish()?;
    }
    let times: Vec<[f64; 2]> =
        frames.iter().enumerate().map(|(t, f)| [t as f64, (f.time_us - first) as f64 * 1e-6]).collect();
    text::write_rows(&layout.timestamps(), &times)?;
    instance_masks::write_instances_and_notes(&layout, &instances, options.dynamic_masks)?;
    let marker = DoneMarker {
        converter: format!(
            "dggt-convert {} (nuscenes {}, {}, {})",
            env!("CARGO_PKG_VERSION"),
            scene_row.name,
            log.location,
            options.rate.describe()
        ),
        source: tables.root.clone(),
        frames: frames.len(),
        cameras: options.cameras.clone(),
        instances: instances.len(),
        lidar_frames: frames.len(),
        provenance: None,
    };
    write_done(scene, &marker)?;
    progress(frames.len() as u64);
    Ok(SceneSummary { name: scene_row.name.clone(), frames: frames.len(), instances: instances.len() })
}
