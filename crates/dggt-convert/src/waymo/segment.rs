//! One Waymo segment (a TFRecord of `Frame`s) streamed record by record into one scene folder of drivestudio's
//! Waymo export ([`dggt_data::ExportVariant::Waymo`]); frame `t` is record `t`.
//!
//! | path | content |
//! |---|---|
//! | `images/{t:03}_{cam}.jpg` | the record's JPEG bytes, unchanged |
//! | `intrinsics/{cam}.txt` | `f_u f_v c_u c_v k1 k2 p1 p2 k3`, one per line, from the first frame |
//! | `extrinsics/{cam}.txt` | 4x4 camera -> ego, Waymo camera axes (x forward, y left, z up), from the first frame |
//! | `ego_pose/{t:03}.txt` | 4x4 `Frame.pose`: ego -> the log's world |
//! | `timestamps.txt` | `t seconds` per frame, seconds since the first frame's `timestamp_micros` |
//! | `lidar/{t:03}.bin` | N x 14 float32 ([`lidar`](super::lidar)), for frames whose lasers have range images |
//! | `dynamic_masks/{all,human,vehicle}/{t:03}_{cam}.png` | as [`DynamicMaskStyle`] says: by default the outlines of the boxes faster than its speed (Waymo's own per-box speeds); drivestudio's, [`MaskRule::SeenAndFasterThan`] 1 m/s as rectangles; calibrated size |
//! | `instances/` | every vehicle, pedestrian and cyclist ([`crate::instances`]) |
//! | `sky_masks/` | with [`SkyMasks::Lidar`] only ([`crate::sky`]) |
//! | `depth_flows_4/{t:03}_{cam}.npy` | with [`DepthFlows::FromBoxes`] only ([`crate::depth_flows`]): the lidar rows' points, flow from the laser labels of the same id at `t + 1` (or `t - 1`), times from `timestamp_micros` |
//! | [`DONE_MARKER`](crate::marker::DONE_MARKER) | written last |
//!
//! Matrices are written with full `f64` precision from the stored doubles. Camera ids are `CameraName - 1`.

use std::path::{Path, PathBuf};

use dggt_data::{ExportLayout, io, text};

use super::frame::{self, CAMERA_COUNT, CameraCalibration, camera_id};
use super::lidar::{self, LaserCalibration, LidarRow};
use super::{ground, proto};
use crate::depth_flows::{DepthFlowWriter, DepthFlows, FrameSample, MapView};
use crate::error::{ConvertError, RecordAt, Result};
use crate::instance_masks;
use crate::instances::InstanceLog;
use crate::marker::{DoneMarker, write_done};
use crate::masks::{DynamicMaskStyle, DynamicMasks, MaskRule};
use crate::sky::{self, SkyMasks};
use dggt_geom::glam::DVec3;

/// Horizontal speed above which a Waymo box counts as moving (m/s).
pub const MOVING_SPEED_M_S: f64 = 1.0;

/// Which cameras to export (export ids, `CameraName - 1`), and whether to write sky masks and depth-flow maps.
#[derive(Debug, Clone, PartialEq)]
pub struct WaymoOptions {
    pub cameras: Vec<usize>,
    pub sky_masks: SkyMasks,
    pub depth_flows: DepthFlows,
    pub dynamic_masks: DynamicMaskStyle,
}

impl Default for WaymoOptions {
    fn default() -> Self {
        Self {
            cameras: (0..CAMERA_COUNT).collect(),
            sky_masks: SkyMasks::None,
            depth_flows: DepthFlows::None,
            dynamic_masks: DynamicMaskStyle::default(),
        }
    }
}

/// What a converted segment holds.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentSummary {
    pub scene: PathBuf,
    pub frames: usize,
    pub images: usize,
    pub lidar_frames: usize,
    pub instances: usize,
}

/// The calibration read from the first frame's context.
struct Calibration {
    cameras: Vec<CameraCalibration>,
    lasers: Vec<LaserCalibration>,
}

/// Converts the segment at `input` into the scene folder `scene`; `progress` gets the bytes read so far after
/// every frame.
pub fn convert_segment(
    input: &Path,
    scene: &Path,
    options: &WaymoOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<SegmentSummary> {
    let layout = ExportLayout::new(scene);
    let mut reader = crate::tfrecord::RecordReader::open(input)?;
    let mut calibration: Option<Calibration> = None;
    let mut instances = InstanceLog::default();
    let mut times_us = Vec::new();
    let mut depth_flows = (options.depth_flows == DepthFlows::FromBoxes).then(|| DepthFlowWriter::new(&layout, input));
    let (mut images, mut lidar_frames) = (0, 0);
    while let Some((record, payload)) = reader.next_record()? {
        let at = RecordAt { path: input, record };
        let frame = proto::decode_frame(payload).map_err(|source| ConvertError::Decode {
            path: input.to_owned(),
            record,
            message: "waymo.open_dataset.Frame",
            source,
        })?;
        let calibration = match &calibration {
            Some(calibration) => calibration,
            None => calibration.insert(first_calibration(at, &frame, options, &layout)?),
        };
        let (pose_rows, world_from_ego) = frame::frame_pose(at, &frame)?;
        text::write_rows(&layout.ego_pose(record), &pose_rows)?;
        times_us.push(frame.timestamp_micros.ok_or_else(|| at.content("timestamp_micros", "none"))?);
        images += write_images(at, &frame, options, &layout)?;
        let global_from_vehicle = lidar::matrix(&pose_rows);
        let lidar_rows = lidar::frame_points(at, &frame, &calibration.lasers, &global_from_vehicle)?;
        if let Some(mut rows) = lidar_rows.clone() {
            ground::mark_ground(&mut rows);
            write_lidar_rows(&layout.lidar(record), &rows)?;
            lidar_frames += 1;
        }
        let boxes = frame::laser_boxes(at, &frame.laser_labels)?;
        instances.register(&boxes);
        // A row's point: columns 3..6, vehicle frame.
        let point = |r: &LidarRow| DVec3::new(r[3].into(), r[4].into(), r[5].into());
        for camera in calibration.cameras.iter().filter(|c| options.cameras.contains(&c.id)) {
            let (rule, shape) = options.dynamic_masks.rule_and_shape(MaskRule::SeenAndFasterThan(MOVING_SPEED_M_S));
            let masks = DynamicMasks::draw(&camera.camera, &boxes, rule, shape);
            masks.write(&layout, record, camera.id)?;
            instance_masks::write(&layout, (record, camera.id), &camera.camera, &boxes, &instances)?;
            if options.sky_masks == SkyMasks::Lidar {
                // A frame without lidar gets a mask without sky.
                let points = lidar_rows.iter().flatten().map(point);
                sky::write_lidar_sky_mask(
                    &layout,
                    record,
                    camera.id,
                    &sky::lidar_sky_mask(&camera.camera, points, sky::TopBeam::Unknown),
                )?;
            }
        }
        if let Some(writer) = &mut depth_flows {
            let time_s = (times_us[record] - times_us[0]) as f64 * 1e-6;
            let in_view = calibration.cameras.iter().filter(|c| options.cameras.contains(&c.id));
            let views = in_view.map(|c| MapView::on_ego(c.id, &c.camera, &world_from_ego)).collect();
            let points = lidar_rows.as_ref().map(|rows| rows.iter().map(point));
            writer.push(FrameSample::in_ego(record, time_s, &world_from_ego, points, &boxes, views))?;
        }
        instances.add_frame(record, &world_from_ego, &boxes);
        progress(reader.bytes_read());
    }
    let frames = times_us.len();
    if frames == 0 {
        return Err(RecordAt { path: input, record: 0 }.content("at least one Frame record", "an empty file"));
    }
    let times: Vec<[f64; 2]> =
        times_us.iter().enumerate().map(|(t, us)| [t as f64, (us - times_us[0]) as f64 * 1e-6]).collect();
    text::write_rows(&layout.timestamps(), &times)?;
    if let Some(writer) = depth_flows {
        writer.finish()?;
    }
    instance_masks::write_instances_and_notes(&layout, &instances, options.dynamic_masks)?;
    let marker = DoneMarker {
        converter: format!("dggt-convert {} (waymo)", env!("CARGO_PKG_VERSION")),
        source: input.to_owned(),
        frames,
        cameras: options.cameras.clone(),
        instances: instances.len(),
        lidar_frames,
        provenance: None,
    };
    write_done(scene, &marker)?;
    Ok(SegmentSummary { scene: scene.to_owned(), frames, images, lidar_frames, instances: instances.len() })
}

/// Reads the calibration from the first frame and writes the chosen cameras' intrinsics and extrinsics.
fn first_calibration(
    at: RecordAt,
    frame: &proto::Frame,
    options: &WaymoOptions,
    layout: &ExportLayout,
) -> Result<Calibration> {
    let context = frame.context.as_ref().ok_or_else(|| at.content("a context with the calibrations", "none"))?;
    let cameras = frame::camera_calibrations(at, context)?;
    for &id in &options.cameras {
        let camera = cameras.iter().find(|c| c.id == id).ok_or_else(|| {
            let present: Vec<usize> = cameras.iter().map(|c| c.id).collect();
            at.content(format!("a calibration for camera {id}"), format!("calibrations for cameras {present:?}"))
        })?;
        text::write_rows(&layout.intrinsics(id), &camera.intrinsic.map(|v| [v]))?;
        text::write_rows(&layout.extrinsics(id), &camera.extrinsic)?;
    }
    Ok(Calibration { cameras, lasers: lidar::laser_calibrations(at, context)? })
}

/// Writes the chosen cameras' JPEGs of one frame; returns how many.
fn write_images(at: RecordAt, frame: &proto::Frame, options: &WaymoOptions, layout: &ExportLayout) -> Result<usize> {
    let mut written = 0;
    for image in &frame.images {
        let id = camera_id(at, image.name, "a camera image")?;
        if !options.cameras.contains(&id) {
            continue;
        }
        let bytes = image.image.as_deref().unwrap_or_default();
        if !bytes.starts_with(&[0xFF, 0xD8]) {
            return Err(at.content(
                format!("camera {}: a JPEG image", id + 1),
                format!("{} bytes without the JPEG marker", bytes.len()),
            ));
        }
        io::write_atomically(&layout.image(at.record, id), bytes)?;
        written += 1;
    }
    Ok(written)
}

fn write_lidar_rows(path: &Path, rows: &[LidarRow]) -> Result<()> {
    let bytes: Vec<u8> = rows.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    Ok(io::write_atomically(path, &bytes)?)
}
