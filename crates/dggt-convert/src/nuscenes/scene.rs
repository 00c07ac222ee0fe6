//! One nuScenes scene (a row of the `scene` table) into one scene folder of drivestudio's nuScenes export
//! ([`dggt_data::ExportVariant::NuScenes`]), key frames only: frame `t` is the scene's `t`-th sample (2 Hz),
//! drivestudio's default (its `--interpolate_N 0`).
//!
//! | path | content |
//! |---|---|
//! | `images/{t:03}_{cam}.jpg` | a copy of the camera's key-frame JPEG |
//! | `intrinsics/{cam}.txt` | `K00 K11 K02 K12 0 0 0 0 0`, one per line (the images are undistorted) |
//! | `extrinsics/{t:03}_{cam}.txt` | 4x4 camera -> global, OpenCV axes: `global_from_ego(the camera's own ego_pose) · ego_from_camera` |
//! | `lidar_pose/{t:03}.txt` | 4x4 LIDAR_TOP -> global: `global_from_ego(the lidar's ego_pose) · ego_from_lidar` |
//! | `lidar/{t:03}.bin` | N x 4 float32 `x y z intensity` in the **LIDAR_TOP frame** (x right, y forward, z up) |
//! | `timestamps.txt` | `t seconds` per frame, since the first sample |
//! | `dynamic_masks/{all,human,vehicle}/{t:03}_{cam}.png` | every annotated box of the class ([`MaskRule::EveryBox`]), moved from global into the camera's ego frame |
//! | `instances/` | the annotations' instances ([`crate::instances`]); `obj_to_world` in the global frame |
//! | `sky_masks/` | with [`SkyMasks::Lidar`] only ([`crate::sky`]) |
//! | [`DONE_MARKER`](crate::marker::DONE_MARKER) | written last |
//!
//! Frames: global (the log's world, [`LogWorld`]), ego (vehicle, forward-left-up), [`Sweep`] (LIDAR_TOP),
//! [`Camera`] (OpenCV axes). Export camera ids: 0 CAM_FRONT, 1 CAM_FRONT_LEFT, 2 CAM_FRONT_RIGHT, 3 CAM_BACK_LEFT,
//! 4 CAM_BACK_RIGHT, 5 CAM_BACK.

use std::path::Path;

use dggt_data::{ExportLayout, ExportVariant, io, text};
use dggt_geom::glam::DVec3;
use dggt_geom::{Camera, Ego, ImageSize, LogWorld, PinholeIntrinsics, Rigid, Sweep};

use super::tables::{AnnotationRow, SampleDataRow, SampleRow, Tables};
use crate::boxes::{AnnotatedBox, ObjectBox, ObjectClass};
use crate::camera::{Distortion, EgoCamera};
use crate::error::{ConvertError, Result};
use crate::instances::InstanceLog;
use crate::marker::{DoneMarker, write_done};
use crate::masks::{DynamicMasks, MaskRule};
use crate::sky::{self, SkyMasks};

/// What a converted scene holds.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSummary {
    pub name: String,
    pub frames: usize,
    pub instances: usize,
}

/// The categories that masks and `instances/` keep, and their class (drivestudio's nuScenes lists).
const MASKED_CATEGORIES: &[(&str, ObjectClass)] = &[
    ("animal", ObjectClass::Human),
    ("human.pedestrian.adult", ObjectClass::Human),
    ("human.pedestrian.child", ObjectClass::Human),
    ("human.pedestrian.construction_worker", ObjectClass::Human),
    ("human.pedestrian.personal_mobility", ObjectClass::Human),
    ("human.pedestrian.police_officer", ObjectClass::Human),
    ("human.pedestrian.stroller", ObjectClass::Human),
    ("human.pedestrian.wheelchair", ObjectClass::Human),
    ("vehicle.bicycle", ObjectClass::Human),
    ("vehicle.motorcycle", ObjectClass::Human),
    ("vehicle.bus.bendy", ObjectClass::Vehicle),
    ("vehicle.bus.rigid", ObjectClass::Vehicle),
    ("vehicle.car", ObjectClass::Vehicle),
    ("vehicle.construction", ObjectClass::Vehicle),
    ("vehicle.emergency.ambulance", ObjectClass::Vehicle),
    ("vehicle.emergency.police", ObjectClass::Vehicle),
    ("vehicle.trailer", ObjectClass::Vehicle),
    ("vehicle.truck", ObjectClass::Vehicle),
];

/// A box of a masked class in the global frame.
struct GlobalBox {
    id: String,
    class_name: &'static str,
    class: ObjectClass,
    global_from_box: Rigid<LogWorld, ObjectBox>,
    /// Length, width, height.
    size: DVec3,
}

impl GlobalBox {
    /// The box in the ego frame whose pose in the global frame is `global_from_ego`.
    fn in_ego(&self, global_from_ego: &Rigid<LogWorld, Ego>) -> AnnotatedBox {
        AnnotatedBox {
            id: self.id.clone(),
            class_name: self.class_name,
            class: self.class,
            ego_from_box: global_from_ego.inverse() * self.global_from_box,
            size: self.size,
            speed: 0.0,
            has_points: true,
        }
    }
}

/// A sensor reading with its poses: `global_from_ego` at the reading's own time, and the sensor's mounting.
struct Reading<'a, S> {
    data: &'a SampleDataRow,
    global_from_ego: Rigid<LogWorld, Ego>,
    ego_from_sensor: Rigid<Ego, S>,
}

impl<'a, S: dggt_geom::frames::Frame> Reading<'a, S> {
    fn of(tables: &'a Tables, sample: &SampleRow, channel: &str) -> Result<Self> {
        let data = tables.key_frame(sample, channel)?;
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
        let path = tables.file_of(self.data);
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

/// The sample's annotations of the masked classes.
fn global_boxes(tables: &Tables, sample: &SampleRow) -> Result<Vec<GlobalBox>> {
    let mut boxes = Vec::new();
    for annotation in tables.annotations(sample) {
        let referrer = format!("sample_annotation `{}`", annotation.token);
        let instance = tables.instance.get(&annotation.instance_token, &referrer)?;
        let category = tables.category.get(&instance.category_token, &format!("instance `{}`", instance.token))?;
        let Some(&(class_name, class)) = MASKED_CATEGORIES.iter().find(|(name, _)| *name == category.name) else {
            continue;
        };
        boxes.push(global_box(tables, annotation, class_name, class)?);
    }
    Ok(boxes)
}

fn global_box(
    tables: &Tables,
    annotation: &AnnotationRow,
    class_name: &'static str,
    class: ObjectClass,
) -> Result<GlobalBox> {
    let table = &tables.sample_annotation;
    let [width, length, height] = annotation.size;
    if !annotation.size.iter().all(|v| v.is_finite() && *v > 0.0) {
        return Err(table.error(
            &annotation.token,
            "a positive finite size (w, l, h)",
            format!("{:?}", annotation.size),
        ));
    }
    Ok(GlobalBox {
        id: annotation.instance_token.clone(),
        class_name,
        class,
        global_from_box: table.rigid(&annotation.token, annotation.rotation, annotation.translation)?,
        size: DVec3::new(length, width, height),
    })
}

/// A `.pcd.bin` sweep: N x 5 float32 (x, y, z, intensity, ring) in the lidar frame.
fn sweep_points(tables: &Tables, reading: &Reading<Sweep>) -> Result<Vec<[f32; 5]>> {
    let bytes = reading.bytes(tables)?;
    if bytes.len() % 20 != 0 {
        return Err(ConvertError::Table {
            path: tables.file_of(reading.data),
            expected: format!("sample_data `{}`: N x 5 float32 (a multiple of 20 bytes)", reading.data.token),
            found: format!("{} bytes", bytes.len()),
        });
    }
    Ok(bytes
        .chunks_exact(20)
        .map(|row| std::array::from_fn(|i| f32::from_le_bytes(row[i * 4..i * 4 + 4].try_into().expect("4 bytes"))))
        .collect())
}

/// Writes one sample as frame `t`; returns the boxes in the lidar's ego frame and that ego's global pose.
fn write_frame(
    tables: &Tables,
    sample: &SampleRow,
    t: usize,
    cameras: &[usize],
    sky_masks: SkyMasks,
    layout: &ExportLayout,
) -> Result<(Vec<AnnotatedBox>, Rigid<LogWorld, Ego>)> {
    let lidar = Reading::<Sweep>::of(tables, sample, "LIDAR_TOP")?;
    let points = sweep_points(tables, &lidar)?;
    let rows: Vec<u8> = points.iter().flat_map(|p| p[..4].iter().flat_map(|v| v.to_le_bytes())).collect();
    io::write_atomically(&layout.lidar(t), &rows)?;
    let global_from_lidar = lidar.global_from_sensor();
    text::write_rows(&layout.lidar_pose(t), &global_from_lidar.to_rows())?;
    let boxes = global_boxes(tables, sample)?;
    let names = ExportVariant::NuScenes.camera_names();
    for &id in cameras {
        let channel = names[id];
        let reading = Reading::<Camera>::of(tables, sample, channel)?;
        let camera = camera_projection(tables, &reading)?;
        io::write_atomically(&layout.image(t, id), &reading.bytes(tables)?)?;
        text::write_rows(&layout.extrinsics_at(t, id), &reading.global_from_sensor().to_rows())?;
        let in_ego: Vec<AnnotatedBox> = boxes.iter().map(|b| b.in_ego(&reading.global_from_ego)).collect();
        DynamicMasks::draw(&camera, &in_ego, MaskRule::EveryBox).write(layout, t, id)?;
        if sky_masks == SkyMasks::Lidar {
            let ego_from_lidar = reading.global_from_ego.inverse() * global_from_lidar;
            let in_ego = points
                .iter()
                .map(|p| ego_from_lidar.transform_point(DVec3::new(p[0].into(), p[1].into(), p[2].into())));
            sky::write_lidar_sky_mask(layout, t, id, &sky::lidar_sky_mask(&camera, in_ego))?;
        }
        if t == 0 {
            let k = camera.intrinsics;
            text::write_rows(&layout.intrinsics(id), &[k.fx, k.fy, k.cx, k.cy, 0.0, 0.0, 0.0, 0.0, 0.0].map(|v| [v]))?;
        }
    }
    let boxes_in_lidar_ego = boxes.iter().map(|b| b.in_ego(&lidar.global_from_ego)).collect();
    Ok((boxes_in_lidar_ego, lidar.global_from_ego))
}

/// Converts scene number `index` of `tables` into the scene folder `scene`, the chosen export cameras only;
/// `progress` gets the number of samples written so far.
pub fn convert_scene(
    tables: &Tables,
    index: usize,
    scene: &Path,
    cameras: &[usize],
    sky_masks: SkyMasks,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<SceneSummary> {
    let layout = ExportLayout::new(scene);
    let names = ExportVariant::NuScenes.camera_names();
    if let Some(unknown) = cameras.iter().find(|&&id| id >= names.len()) {
        return Err(ConvertError::Table {
            path: tables.sensor.path.clone(),
            expected: format!("a nuScenes export camera id 0..={} ({})", names.len() - 1, names.join(", ")),
            found: format!("camera {unknown}"),
        });
    }
    let (scene_row, samples) = tables.scene_samples(index)?;
    let mut instances = InstanceLog::default();
    for (t, sample) in samples.iter().enumerate() {
        progress(t as u64);
        let (boxes, global_from_ego) = write_frame(tables, sample, t, cameras, sky_masks, &layout)?;
        instances.add_frame(t, &global_from_ego, &boxes);
    }
    let first = samples[0].timestamp;
    let times: Vec<[f64; 2]> =
        samples.iter().enumerate().map(|(t, s)| [t as f64, (s.timestamp - first) as f64 * 1e-6]).collect();
    text::write_rows(&layout.timestamps(), &times)?;
    instances.write(&layout)?;
    let marker = DoneMarker {
        converter: format!("dggt-convert {} (nuscenes)", env!("CARGO_PKG_VERSION")),
        source: tables.root.join(&scene_row.name),
        frames: samples.len(),
        cameras: cameras.to_vec(),
        instances: instances.len(),
        lidar_frames: samples.len(),
    };
    write_done(scene, &marker)?;
    progress(samples.len() as u64);
    Ok(SceneSummary { name: scene_row.name.clone(), frames: samples.len(), instances: instances.len() })
}
