//! A decoded Waymo `Frame` checked and turned into the converter's types: camera calibrations keyed by camera
//! name (never by list position: `images` come in no fixed order), the rigid frame pose, and the laser labels.
//!
//! Export camera ids are `CameraName - 1` (0 FRONT, 1 FRONT_LEFT, 2 FRONT_RIGHT, 3 SIDE_LEFT, 4 SIDE_RIGHT).
//! Matrices stay as the row-major `double`s the record holds, so that the export's text files carry them
//! unchanged; each is also checked to be rigid.

use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{Ego, ImageSize, LogWorld, PinholeIntrinsics, Rigid, WaymoCamera};

use super::proto;
use crate::boxes::{AnnotatedBox, ObjectClass};
use crate::camera::{Distortion, EgoCamera};
use crate::error::{RecordAt, Result};

/// Cameras of Waymo v1 (`CameraName` 1..=5).
pub const CAMERA_COUNT: usize = 5;

/// A row-major 4x4 matrix as stored.
pub type Rows4 = [[f64; 4]; 4];

/// The export id of a `CameraName`.
pub fn camera_id(at: RecordAt, name: Option<i32>, what: &str) -> Result<usize> {
    match name {
        Some(name @ 1..=5) => Ok(name as usize - 1),
        other => Err(at.content(format!("{what} with a camera name 1..=5"), format!("{other:?}"))),
    }
}

/// The 16 values of a `Transform` as rows, checked to be finite and rigid.
pub fn rigid_rows<To, From>(
    at: RecordAt,
    what: &str,
    transform: Option<&proto::Transform>,
) -> Result<(Rows4, Rigid<To, From>)> {
    let values = transform.map(|t| t.transform.as_slice()).unwrap_or_default();
    if values.len() != 16 {
        return Err(at.content(format!("{what}: a 4x4 matrix (16 doubles)"), format!("{} values", values.len())));
    }
    let rows: Rows4 = std::array::from_fn(|i| std::array::from_fn(|j| values[i * 4 + j]));
    let rigid = Rigid::from_rows(rows).map_err(|e| at.content(format!("{what}: a rigid transform"), e.to_string()))?;
    Ok((rows, rigid))
}

/// One camera's calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraCalibration {
    /// Export id (`CameraName - 1`).
    pub id: usize,
    /// `[f_u, f_v, c_u, c_v, k1, k2, p1, p2, k3]` as stored.
    pub intrinsic: [f64; 9],
    /// Camera -> ego in Waymo camera axes (x forward, y left, z up), as stored.
    pub extrinsic: Rows4,
    /// The same camera for projection (OpenCV axes, with distortion).
    pub camera: EgoCamera,
}

/// The context's camera calibrations, ordered by export id, one per camera.
pub fn camera_calibrations(at: RecordAt, context: &proto::Context) -> Result<Vec<CameraCalibration>> {
    let mut calibrations: Vec<CameraCalibration> =
        context.camera_calibrations.iter().map(|c| camera_calibration(at, c)).collect::<Result<_>>()?;
    calibrations.sort_by_key(|c| c.id);
    if let Some(pair) = calibrations.windows(2).find(|pair| pair[0].id == pair[1].id) {
        return Err(at.content("one calibration per camera", format!("two for camera {}", pair[0].id + 1)));
    }
    Ok(calibrations)
}

fn camera_calibration(at: RecordAt, calibration: &proto::CameraCalibration) -> Result<CameraCalibration> {
    let id = camera_id(at, calibration.name, "a camera calibration")?;
    let what = format!("calibration of camera {}", id + 1);
    let intrinsic: [f64; 9] =
        calibration.intrinsic.as_slice().try_into().map_err(|_| {
            at.content(format!("{what}: 9 intrinsics"), format!("{} values", calibration.intrinsic.len()))
        })?;
    let (extrinsic, ego_from_camera) =
        rigid_rows::<Ego, WaymoCamera>(at, &format!("{what}: extrinsic"), calibration.extrinsic.as_ref())?;
    let [fx, fy, cx, cy, k1, k2, p1, p2, k3] = intrinsic;
    let intrinsics = PinholeIntrinsics::new(fx, fy, cx, cy)
        .map_err(|e| at.content(format!("{what}: valid intrinsics"), e.to_string()))?;
    let size = match (calibration.width, calibration.height) {
        (Some(w), Some(h)) if w > 0 && h > 0 => ImageSize::new(w as u32, h as u32).ok(),
        _ => None,
    }
    .ok_or_else(|| {
        at.content(
            format!("{what}: a positive width and height"),
            format!("{:?} x {:?}", calibration.width, calibration.height),
        )
    })?;
    let camera = EgoCamera {
        intrinsics,
        distortion: Distortion { k1, k2, p1, p2, k3 },
        camera_from_ego: dggt_geom::axes::ego_from_opencv_camera(&ego_from_camera).inverse(),
        size,
    };
    Ok(CameraCalibration { id, intrinsic, extrinsic, camera })
}

/// The frame pose (vehicle -> global), as stored and as a rigid transform.
pub fn frame_pose(at: RecordAt, frame: &proto::Frame) -> Result<(Rows4, Rigid<LogWorld, Ego>)> {
    rigid_rows(at, "frame pose (vehicle -> global)", frame.pose.as_ref())
}

/// The laser labels of the masked classes (vehicles, pedestrians, cyclists), as boxes in the frame's ego frame.
///
/// Whether the lidar saw a box is `num_top_lidar_points_in_box > 0` when any label of the frame carries that
/// count, else `num_lidar_points_in_box > 0`.
pub fn laser_boxes(at: RecordAt, labels: &[proto::Label]) -> Result<Vec<AnnotatedBox>> {
    let top_counts = labels.iter().any(|l| l.num_top_lidar_points_in_box.is_some());
    let mut boxes = Vec::new();
    for (index, label) in labels.iter().enumerate() {
        let (class, class_name) = match label.r#type {
            Some(1) => (ObjectClass::Vehicle, "Vehicle"),
            Some(2) => (ObjectClass::Human, "Pedestrian"),
            Some(4) => (ObjectClass::Human, "Cyclist"),
            _ => continue,
        };
        let points = if top_counts { label.num_top_lidar_points_in_box } else { label.num_lidar_points_in_box };
        let what = format!("laser label {index}");
        let id = label.id.clone().ok_or_else(|| at.content(format!("{what}: an object id"), "none"))?;
        let b = label.r#box.as_ref().ok_or_else(|| at.content(format!("{what}: a box"), "none"))?;
        let values = [b.center_x, b.center_y, b.center_z, b.length, b.width, b.height, b.heading];
        let [x, y, z, length, width, height, heading] = values.map(|v| v.filter(|v| v.is_finite()));
        let (Some(x), Some(y), Some(z), Some(length), Some(width), Some(height), Some(heading)) =
            (x, y, z, length, width, height, heading)
        else {
            return Err(at.content(format!("{what}: finite centre, size and heading"), format!("{b:?}")));
        };
        let ego_from_box = Rigid::from_rotation_translation(DQuat::from_rotation_z(heading), DVec3::new(x, y, z))
            .map_err(|e| at.content(format!("{what}: a box pose"), e.to_string()))?;
        let speed = label.metadata.as_ref().map_or(0.0, |m| m.speed_x.unwrap_or(0.0).hypot(m.speed_y.unwrap_or(0.0)));
        boxes.push(AnnotatedBox {
            id,
            class_name,
            class,
            ego_from_box,
            size: DVec3::new(length, width, height),
            speed,
            has_points: points.unwrap_or(0) > 0,
        });
    }
    Ok(boxes)
}
