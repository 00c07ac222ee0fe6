//! One Argoverse 2 sensor log into one scene folder of drivestudio's Argoverse 2 export
//! ([`dggt_data::ExportVariant::Argoverse2`]); frame `t` is the `t`-th lidar sweep kept.
//!
//! A sweep is kept when every chosen camera has an image within ±25 ms of it and the sweep and each of those
//! images have an ego pose row (drivestudio's rule). Export camera ids: 0 ring_front_center (portrait),
//! 1 ring_front_left, 2 ring_front_right, 3 ring_side_left, 4 ring_side_right, 5 ring_rear_left,
//! 6 ring_rear_right.
//!
//! | path | content |
//! |---|---|
//! | `images/{t:03}_{cam}.jpg` | [`Lens::Undistorted`]: the log's images resampled to the pinhole camera ([`crate::undistort`]), JPEG quality 95; [`Lens::AsRecorded`]: the log's JPEG bytes, unchanged (drivestudio re-encodes them) |
//! | `intrinsics/{cam}.txt` | `fx fy cx cy 0 0 0 0 0`: the pinhole camera the images follow once undistorted; as recorded, the radial distortion is dropped, as drivestudio does |
//! | `extrinsics/{cam}.txt` | 4x4 camera -> ego, OpenCV camera axes |
//! | `ego_pose/{t:03}.txt` | 4x4 ego -> city at the sweep's time (shared by the cameras) |
//! | `timestamps.txt` | `t seconds` per frame, seconds since the first kept sweep |
//! | `lidar/{t:03}.bin` | N x 4 float32: x y z (m, ego frame at the sweep's time), intensity (0-255) |
//! | `dynamic_masks/{all,human,vehicle}/` | as `options.dynamic_masks` says ([`DynamicMaskStyle`]): by default the outlines of the objects whose tracks move, each box moved along its track to the image's time and seen from the ego at that time; drivestudio's, every box of the masked categories ([`MaskRule::EveryBox`]) at the sweep's time; pinhole cameras |
//! | `sky_masks/` | with [`SkyMasks::Lidar`] only ([`crate::sky`]) |
//! | `depth_flows_4/{t:03}_{cam}.npy` | with [`DepthFlows::FromBoxes`] only ([`crate::depth_flows`]): the sweep's points, flow from the annotations of the same `track_uuid` at the next kept sweep (or the previous), times from the sweeps' `timestamp_ns` |
//! | `instances/` | those boxes; `obj_to_world` = ego -> city at the sweep · object -> ego |
//! | [`DONE_MARKER`](crate::marker::DONE_MARKER) | written last |

use std::path::{Path, PathBuf};

use dggt_data::{ExportLayout, ExportVariant, io, text};
use dggt_geom::glam::DVec3;
use std::collections::{BTreeMap, HashMap};

use crate::boxes::AnnotatedBox;
use dggt_geom::{Ego, ImageSize, LogWorld, PinholeIntrinsics, Rigid};

use super::tables::{self, CameraCalibration};
use crate::batch::ConvertOptions;
use crate::box_flow::WorldBox;
use crate::camera::{Distortion, EgoCamera};
use crate::depth_flows::{DepthFlowWriter, DepthFlows, FrameSample, MapView};
use crate::error::{ConvertError, Result};
use crate::feather::Table;
use crate::instance_masks;
use crate::instances::InstanceLog;
use crate::marker::{DoneMarker, write_done};
use crate::masks::{DynamicMaskStyle, DynamicMasks, MaskRule};
use crate::sky::{self, SkyMasks};
use crate::tracks::Tracks;
use crate::undistort::{Lens, Undistortion};

/// JPEG quality of the resampled images.
const UNDISTORTED_JPEG_QUALITY: u8 = 95;

/// Largest offset between a sweep and the image paired with it (ns).
pub const PAIRING_WINDOW_NS: i64 = 25_000_000;

/// What a converted log holds.
#[derive(Debug, Clone, PartialEq)]
pub struct LogSummary {
    pub scene: PathBuf,
    pub frames: usize,
    /// Sweeps left out for want of an image or a pose.
    pub dropped_sweeps: usize,
    pub instances: usize,
}

/// One chosen camera.
struct LogCamera {
    id: usize,
    name: &'static str,
    calibration: CameraCalibration,
    /// Image timestamps (ns), sorted.
    images: Vec<i64>,
}

impl LogCamera {
    fn image_path(&self, log: &Path, time_ns: i64) -> PathBuf {
        log.join("sensors/cameras").join(self.name).join(format!("{time_ns}.jpg"))
    }

    /// The camera as recorded: the export's pinhole camera with the lens's radial distortion.
    fn recorded_camera(&self, log: &Path) -> Result<EgoCamera> {
        let [k1, k2, k3] = self.calibration.radial;
        Ok(EgoCamera { distortion: Distortion { k1, k2, k3, p1: 0.0, p2: 0.0 }, ..self.export_camera(log)? })
    }

    /// The pinhole camera the export describes (no distortion).
    fn export_camera(&self, log: &Path) -> Result<EgoCamera> {
        let [fx, fy, cx, cy] = self.calibration.pinhole;
        let invalid = |e: dggt_geom::GeomError| ConvertError::Table {
            path: log.join("calibration/intrinsics.feather"),
            expected: format!("valid intrinsics for `{}`", self.name),
            found: e.to_string(),
        };
        Ok(EgoCamera {
            intrinsics: PinholeIntrinsics::new(fx, fy, cx, cy).map_err(invalid)?,
            distortion: Distortion::default(),
            camera_from_ego: self.calibration.ego_from_camera.inverse(),
            size: ImageSize::new(self.calibration.width, self.calibration.height).map_err(invalid)?,
        })
    }

    /// The image nearest `time_ns` within the pairing window.
    fn pair(&self, time_ns: i64) -> Option<i64> {
        let after = self.images.partition_point(|&t| t < time_ns);
        let candidates = [after.checked_sub(1), Some(after)];
        candidates
            .into_iter()
            .flatten()
            .filter_map(|i| self.images.get(i).copied())
            .min_by_key(|t| (t - time_ns).abs())
            .filter(|t| (t - time_ns).abs() <= PAIRING_WINDOW_NS)
    }
}

/// The numbers in the file names `<timestamp_ns>.<extension>` of a folder, sorted.
fn timestamps_in(folder: &Path, extension: &str) -> Result<Vec<i64>> {
    let entries = std::fs::read_dir(folder).map_err(|e| ConvertError::io(folder, e))?;
    let mut times = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| ConvertError::io(folder, e))?.path();
        if path.extension().is_none_or(|ext| ext != extension) {
            continue;
        }
        let time = path.file_stem().and_then(|s| s.to_str()).and_then(|s| s.parse().ok()).ok_or_else(|| {
            ConvertError::Table {
                path: path.clone(),
                expected: "a file named by its timestamp in ns".into(),
                found: "another name".into(),
            }
        })?;
        times.push(time);
    }
    times.sort_unstable();
    Ok(times)
}

fn chosen_cameras(log: &Path, cameras: &[usize]) -> Result<Vec<LogCamera>> {
    let names = ExportVariant::Argoverse2.camera_names();
    let mut calibrations = tables::camera_calibrations(log)?;
    cameras
        .iter()
        .map(|&id| {
            let name = *names.get(id).ok_or_else(|| ConvertError::Table {
                path: log.to_owned(),
                expected: format!("an Argoverse 2 export camera id 0..={}", names.len() - 1),
                found: format!("{id}"),
            })?;
            let calibration = calibrations.remove(name).ok_or_else(|| ConvertError::Table {
                path: log.join("calibration/intrinsics.feather"),
                expected: format!("a row for camera `{name}`"),
                found: "none".into(),
            })?;
            let images = timestamps_in(&log.join("sensors/cameras").join(name), "jpg")?;
            Ok(LogCamera { id, name, calibration, images })
        })
        .collect()
}

/// Converts the log folder `log` into the scene folder `scene`, the chosen export cameras only; `progress` gets
/// the number of sweeps handled so far.
pub fn convert_log(
    log: &Path,
    scene: &Path,
    (options, lens): (&ConvertOptions, Lens),
    progress: &(dyn Fn(u64) + Sync),
) -> Result<LogSummary> {
    let layout = ExportLayout::new(scene);
    let cameras = chosen_cameras(log, &options.cameras)?;
    let poses = tables::ego_poses(log)?;
    let mut annotations = tables::annotations(log)?;
    let sweeps = timestamps_in(&log.join("sensors/lidar"), "feather")?;
    let seconds = |time_ns: i64| (time_ns - sweeps.first().copied().unwrap_or_default()) as f64 * 1e-9;
    let tracks = log_tracks(&annotations, &poses, seconds);
    let projections = cameras.iter().map(|camera| camera.export_camera(log)).collect::<Result<Vec<_>>>()?;
    let undistortions = match lens {
        Lens::Undistorted => {
            let recorded = cameras.iter().map(|camera| camera.recorded_camera(log)).collect::<Result<Vec<_>>>()?;
            recorded.iter().map(|camera| Some(Undistortion::of(camera))).collect()
        }
        Lens::AsRecorded => vec![None; cameras.len()],
    };
    let mut instances = InstanceLog::default();
    let annotations_file = log.join("annotations.feather");
    let mut depth_flows =
        (options.depth_flows == DepthFlows::FromBoxes).then(|| DepthFlowWriter::new(&layout, &annotations_file));
    let mut kept = Vec::new();
    for (index, &sweep) in sweeps.iter().enumerate() {
        progress(index as u64);
        let pairs: Option<Vec<i64>> = cameras.iter().map(|c| c.pair(sweep).filter(|t| poses.contains_key(t))).collect();
        let (Some(pairs), Some(world_from_ego)) = (pairs, poses.get(&sweep)) else { continue };
        let t = kept.len();
        let points = write_sweep(&log.join("sensors/lidar").join(format!("{sweep}.feather")), &layout.lidar(t))?;
        instances.register(annotations.get(&sweep).map(Vec::as_slice).unwrap_or_default());
        for (((camera, projection), undistortion), time) in
            cameras.iter().zip(&projections).zip(&undistortions).zip(pairs)
        {
            write_image(&camera.image_path(log, time), &layout.image(t, camera.id), undistortion.as_ref())?;
            let boxes = annotations.get(&sweep).map(Vec::as_slice).unwrap_or_default();
            let boxes: Vec<AnnotatedBox> = match options.dynamic_masks {
                DynamicMaskStyle::MovingOutlines { .. } => {
                    let world_from_image_ego = &poses[&time];
                    let at_view = |b: &AnnotatedBox| tracks.at_view(b.clone(), seconds(time), world_from_image_ego);
                    boxes.iter().map(at_view).collect()
                }
                DynamicMaskStyle::Drivestudio => boxes.to_vec(),
            };
            let (rule, shape) = options.dynamic_masks.rule_and_shape(MaskRule::EveryBox);
            DynamicMasks::draw(projection, &boxes, rule, shape).write(&layout, t, camera.id)?;
            instance_masks::write(&layout, (t, camera.id), projection, &boxes, &instances)?;
            if options.sky_masks == SkyMasks::Lidar {
                let mask = sky::lidar_sky_mask(projection, points.iter().copied(), sky::TopBeam::Unknown);
                sky::write_lidar_sky_mask(&layout, t, camera.id, &mask)?;
            }
        }
        text::write_rows(&layout.ego_pose(t), &world_from_ego.to_rows())?;
        let boxes = annotations.remove(&sweep).unwrap_or_default();
        if let Some(writer) = &mut depth_flows {
            let time_s = (sweep - sweeps[0]) as f64 * 1e-9;
            let views = cameras.iter().zip(&projections).map(|(c, p)| MapView::on_ego(c.id, p, world_from_ego));
            let points = Some(points.iter().copied());
            writer.push(FrameSample::in_ego(t, time_s, world_from_ego, points, &boxes, views.collect()))?;
        }
        instances.add_frame(t, world_from_ego, &boxes);
        kept.push(sweep);
    }
    let Some(&first) = kept.first() else {
        return Err(ConvertError::Table {
            path: log.join("sensors/lidar"),
            expected: "a sweep with an image from every chosen camera within 25 ms, and their poses".into(),
            found: format!("none of {} sweeps", sweeps.len()),
        });
    };
    for (camera, projection) in cameras.iter().zip(&projections) {
        let k = projection.intrinsics;
        text::write_rows(
            &layout.intrinsics(camera.id),
            &[k.fx, k.fy, k.cx, k.cy, 0.0, 0.0, 0.0, 0.0, 0.0].map(|v| [v]),
        )?;
        text::write_rows(&layout.extrinsics(camera.id), &camera.calibration.ego_from_camera.to_rows())?;
    }
    let times: Vec<[f64; 2]> = kept.iter().enumerate().map(|(t, ns)| [t as f64, (ns - first) as f64 * 1e-9]).collect();
    text::write_rows(&layout.timestamps(), &times)?;
    if let Some(writer) = depth_flows {
        writer.finish()?;
    }
    instance_masks::write_instances_and_notes(&layout, &instances, options.dynamic_masks)?;
    let marker = DoneMarker {
        converter: format!("dggt-convert {} (argoverse2)", env!("CARGO_PKG_VERSION")),
        source: log.to_owned(),
        frames: kept.len(),
        cameras: cameras.iter().map(|c| c.id).collect(),
        instances: instances.len(),
        lidar_frames: kept.len(),
        provenance: None,
    };
    write_done(scene, &marker)?;
    progress(sweeps.len() as u64);
    Ok(LogSummary {
        scene: scene.to_owned(),
        frames: kept.len(),
        dropped_sweeps: sweeps.len() - kept.len(),
        instances: instances.len(),
    })
}

/// The log's tracks in the city frame: each sweep's annotations placed by the ego pose at the sweep (sweeps
/// without a pose are left out), times from `seconds`.
fn log_tracks(
    annotations: &HashMap<i64, Vec<AnnotatedBox>>,
    poses: &BTreeMap<i64, Rigid<LogWorld, Ego>>,
    seconds: impl Fn(i64) -> f64,
) -> Tracks {
    let frames: Vec<(f64, Vec<WorldBox>)> = annotations
        .iter()
        .filter_map(|(time, boxes)| {
            let world_from_ego = poses.get(time)?;
            Some((seconds(*time), boxes.iter().map(|b| WorldBox::of(b, world_from_ego)).collect()))
        })
        .collect();
    Tracks::new(frames.iter().map(|(t, boxes)| (*t, boxes.as_slice())))
}

/// Writes a sweep's `x y z intensity` rows (ego frame) as float32; returns its points.
fn write_sweep(source: &Path, target: &Path) -> Result<Vec<DVec3>> {
    let table = Table::read(source)?;
    let columns = ["x", "y", "z", "intensity"].map(|name| table.f64_column(name));
    let [x, y, z, intensity] = columns;
    let (x, y, z, intensity) = (x?, y?, z?, intensity?);
    let mut bytes = Vec::with_capacity(x.len() * 16);
    for row in 0..x.len() {
        for value in [x[row], y[row], z[row], intensity[row]] {
            bytes.extend_from_slice(&(value as f32).to_le_bytes());
        }
    }
    io::write_atomically(target, &bytes)?;
    Ok((0..x.len()).map(|row| DVec3::new(x[row], y[row], z[row])).collect())
}

/// Writes the recorded image `source` to `target`: its bytes unchanged, or resampled by `undistortion`.
fn write_image(source: &Path, target: &Path, undistortion: Option<&Undistortion>) -> Result<()> {
    let Some(undistortion) = undistortion else {
        let bytes = std::fs::read(source).map_err(|e| ConvertError::io(source, e))?;
        return Ok(io::write_atomically(target, &bytes)?);
    };
    let recorded = dggt_data::images::read_rgb(source)?;
    let pinhole = undistortion.apply(&recorded).ok_or_else(|| ConvertError::Table {
        path: source.to_owned(),
        expected: "an image of the size calibration/intrinsics.feather gives its camera".into(),
        found: format!("{}x{}", recorded.width(), recorded.height()),
    })?;
    Ok(dggt_data::images::write_jpeg(target, &pinhole, UNDISTORTED_JPEG_QUALITY)?)
}
