//! The Argoverse 2 log tables the converter reads, checked row by row.
//!
//! | file | rows |
//! |---|---|
//! | `calibration/egovehicle_SE3_sensor.feather` | `sensor_name`, `qw qx qy qz` (scalar first), `tx_m ty_m tz_m`: ego <- sensor; cameras in OpenCV axes |
//! | `calibration/intrinsics.feather` | `sensor_name`, `fx_px fy_px cx_px cy_px` (pixels), `k1 k2 k3` (radial), `height_px width_px` |
//! | `city_SE3_egovehicle.feather` | `timestamp_ns` (i64 ns), pose: city <- ego |
//! | `annotations.feather` | `timestamp_ns` (the lidar sweep's), `track_uuid`, `category`, `length_m width_m height_m`, pose: ego <- object |
//!
//! A quaternion whose norm is not 1 (within 1e-3) is a non-rigid pose: an error naming the file and row.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use dggt_geom::frames::Frame;
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{Camera, Ego, LogWorld, Rigid};

use crate::boxes::{AnnotatedBox, ObjectBox, ObjectClass};
use crate::error::{ConvertError, Result};
use crate::feather::Table;

/// Largest accepted deviation of a stored quaternion's norm from 1.
const UNIT_TOLERANCE: f64 = 1e-3;

/// The pose columns of every row: `qw qx qy qz tx_m ty_m tz_m`.
fn poses<To: Frame, From: Frame>(table: &Table) -> Result<Vec<Rigid<To, From>>> {
    let columns = ["qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m"].map(|name| table.f64_column(name));
    let [qw, qx, qy, qz, tx, ty, tz] = columns;
    let (qw, qx, qy, qz, tx, ty, tz) = (qw?, qx?, qy?, qz?, tx?, ty?, tz?);
    (0..table.rows())
        .map(|row| {
            let rotation = DQuat::from_xyzw(qx[row], qy[row], qz[row], qw[row]);
            if (rotation.length() - 1.0).abs() > UNIT_TOLERANCE {
                return Err(ConvertError::Table {
                    path: table.path().to_owned(),
                    expected: format!("row {row}: a unit quaternion (a rigid {} <- {} pose)", To::NAME, From::NAME),
                    found: format!("norm {:.6}", rotation.length()),
                });
            }
            Rigid::from_rotation_translation(rotation, DVec3::new(tx[row], ty[row], tz[row])).map_err(|e| {
                ConvertError::Table {
                    path: table.path().to_owned(),
                    expected: format!("row {row}: a rigid pose"),
                    found: e.to_string(),
                }
            })
        })
        .collect()
}

/// One camera's calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraCalibration {
    /// Camera -> ego, OpenCV camera axes.
    pub ego_from_camera: Rigid<Ego, Camera>,
    /// `fx fy cx cy` in pixels.
    pub pinhole: [f64; 4],
    /// Radial distortion `k1 k2 k3`.
    pub radial: [f64; 3],
    pub width: u32,
    pub height: u32,
}

/// The calibration of every camera by sensor name.
pub fn camera_calibrations(log: &Path) -> Result<HashMap<String, CameraCalibration>> {
    let mounting = Table::read(&log.join("calibration/egovehicle_SE3_sensor.feather"))?;
    let mounts: HashMap<String, Rigid<Ego, Camera>> =
        mounting.string_column("sensor_name")?.into_iter().zip(poses(&mounting)?).collect();
    let intrinsics = Table::read(&log.join("calibration/intrinsics.feather"))?;
    let names = intrinsics.string_column("sensor_name")?;
    let values = ["fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "k3", "width_px", "height_px"]
        .map(|column| intrinsics.f64_column(column));
    let [fx, fy, cx, cy, k1, k2, k3, width, height] = values;
    let (fx, fy, cx, cy, k1, k2, k3, width, height) = (fx?, fy?, cx?, cy?, k1?, k2?, k3?, width?, height?);
    names
        .into_iter()
        .enumerate()
        .map(|(row, name)| {
            let ego_from_camera = *mounts.get(&name).ok_or_else(|| ConvertError::Table {
                path: mounting.path().to_owned(),
                expected: format!("a row for camera `{name}` (intrinsics row {row})"),
                found: "none".into(),
            })?;
            if fx[row] <= 0.0 || fy[row] <= 0.0 || width[row] < 1.0 || height[row] < 1.0 {
                return Err(ConvertError::Table {
                    path: intrinsics.path().to_owned(),
                    expected: format!("row {row}: positive focal lengths and image size"),
                    found: format!("fx {} fy {} size {} x {}", fx[row], fy[row], width[row], height[row]),
                });
            }
            let calibration = CameraCalibration {
                ego_from_camera,
                pinhole: [fx[row], fy[row], cx[row], cy[row]],
                radial: [k1[row], k2[row], k3[row]],
                width: width[row] as u32,
                height: height[row] as u32,
            };
            Ok((name, calibration))
        })
        .collect()
}

/// City <- ego poses by timestamp (ns).
pub fn ego_poses(log: &Path) -> Result<BTreeMap<i64, Rigid<LogWorld, Ego>>> {
    let table = Table::read(&log.join("city_SE3_egovehicle.feather"))?;
    Ok(table.i64_column("timestamp_ns")?.into_iter().zip(poses(&table)?).collect())
}

/// The categories that masks and `instances/` keep, and their class.
const MASKED_CATEGORIES: &[(&str, ObjectClass)] = &[
    ("BICYCLIST", ObjectClass::Human),
    ("DOG", ObjectClass::Human),
    ("MOTORCYCLIST", ObjectClass::Human),
    ("PEDESTRIAN", ObjectClass::Human),
    ("STROLLER", ObjectClass::Human),
    ("WHEELCHAIR", ObjectClass::Human),
    ("WHEELED_DEVICE", ObjectClass::Human),
    ("WHEELED_RIDER", ObjectClass::Human),
    ("ARTICULATED_BUS", ObjectClass::Vehicle),
    ("BOX_TRUCK", ObjectClass::Vehicle),
    ("BUS", ObjectClass::Vehicle),
    ("LARGE_VEHICLE", ObjectClass::Vehicle),
    ("MOTORCYCLE", ObjectClass::Vehicle),
    ("RAILED_VEHICLE", ObjectClass::Vehicle),
    ("REGULAR_VEHICLE", ObjectClass::Vehicle),
    ("SCHOOL_BUS", ObjectClass::Vehicle),
    ("TRUCK", ObjectClass::Vehicle),
    ("TRUCK_CAB", ObjectClass::Vehicle),
    ("VEHICULAR_TRAILER", ObjectClass::Vehicle),
];

/// The category's static name and masked class, or `None` for the categories that are not masked.
pub fn object_class(category: &str) -> Option<(&'static str, ObjectClass)> {
    MASKED_CATEGORIES.iter().find(|(name, _)| *name == category).copied()
}

/// The boxes of the masked classes by sweep timestamp (ns), in the ego frame at that time.
pub fn annotations(log: &Path) -> Result<HashMap<i64, Vec<AnnotatedBox>>> {
    let table = Table::read(&log.join("annotations.feather"))?;
    let times = table.i64_column("timestamp_ns")?;
    let ids = table.string_column("track_uuid")?;
    let categories = table.string_column("category")?;
    let (length, width, height) =
        (table.f64_column("length_m")?, table.f64_column("width_m")?, table.f64_column("height_m")?);
    let points = table.i64_column("num_interior_pts")?;
    let poses = poses::<Ego, ObjectBox>(&table)?;
    let mut by_time: HashMap<i64, Vec<AnnotatedBox>> = HashMap::new();
    for row in 0..table.rows() {
        let Some((class_name, class)) = object_class(&categories[row]) else { continue };
        by_time.entry(times[row]).or_default().push(AnnotatedBox {
            id: ids[row].clone(),
            class_name,
            class,
            ego_from_box: poses[row],
            size: DVec3::new(length[row], width[row], height[row]),
            speed: 0.0,
            has_points: points[row] > 0,
        });
    }
    Ok(by_time)
}
