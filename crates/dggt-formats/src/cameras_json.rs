//! This project's camera file, `cameras.json`: every view's pose and intrinsics with the convention written
//! into the file, so it can be read without this documentation.
//!
//! Convention: OpenCV camera axes (x right, y down, z forward); `world_from_camera` is the camera-to-world
//! 4x4 (its last column is the camera centre) and `camera_from_world` its inverse (the extrinsic `[R | t]`),
//! both as rows; intrinsics `fx fy cx cy` in pixels of `width x height` images spanning `[0, W] x [0, H]`
//! (pixel `(c, r)` centred at `(c + 0.5, r + 0.5)`). What the world frame is, is stated by the writer.

use std::path::Path;

use dggt_geom::{ImageSize, PinholeIntrinsics, WorldFromCamera};
use serde::{Deserialize, Serialize};

use crate::FormatError;

/// One view's camera.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraRecord {
    /// The view's name (also its file stem in the other outputs).
    pub name: String,
    /// Frame index in the source log.
    pub frame: usize,
    /// Camera position in the chosen rig.
    pub camera: usize,
    /// Seconds since the first chosen frame.
    pub time_s: f64,
    pub size: ImageSize,
    pub intrinsics: PinholeIntrinsics,
    pub world_from_camera: WorldFromCamera,
}

/// The convention block written at the top of the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Convention {
    pub axes: String,
    pub world_from_camera: String,
    pub camera_from_world: String,
    pub intrinsics: String,
    /// What the world frame is.
    pub world: String,
}

impl Convention {
    /// The convention of this format, with the writer's description of the world frame.
    pub fn opencv(world: impl Into<String>) -> Self {
        Self {
            axes: "OpenCV camera axes: x right, y down, z forward".into(),
            world_from_camera: "camera-to-world 4x4 as rows; the last column is the camera centre".into(),
            camera_from_world: "world-to-camera 4x4 as rows (the extrinsic [R | t]); the inverse of world_from_camera"
                .into(),
            intrinsics: "fx fy cx cy in pixels; the image spans [0, width] x [0, height]".into(),
            world: world.into(),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct RecordJson {
    name: String,
    frame: usize,
    camera: usize,
    time_s: f64,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    world_from_camera: [[f64; 4]; 4],
    camera_from_world: [[f64; 4]; 4],
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct FileJson {
    convention: Convention,
    views: Vec<RecordJson>,
}

/// Writes `records` with `convention` to `path`.
pub fn write_cameras_json(path: &Path, convention: &Convention, records: &[CameraRecord]) -> Result<(), FormatError> {
    let json = FileJson {
        convention: convention.clone(),
        views: records
            .iter()
            .map(|r| RecordJson {
                name: r.name.clone(),
                frame: r.frame,
                camera: r.camera,
                time_s: r.time_s,
                width: r.size.width,
                height: r.size.height,
                fx: r.intrinsics.fx,
                fy: r.intrinsics.fy,
                cx: r.intrinsics.cx,
                cy: r.intrinsics.cy,
                world_from_camera: r.world_from_camera.to_rows(),
                camera_from_world: r.world_from_camera.inverse().to_rows(),
            })
            .collect(),
    };
    let text = serde_json::to_string_pretty(&json).map_err(|e| FormatError::invalid(path, e.to_string()))?;
    crate::write_file(path, text.as_bytes())
}

/// Reads a `cameras.json`; checks that the two pose matrices of each view are inverses.
pub fn read_cameras_json(path: &Path) -> Result<(Convention, Vec<CameraRecord>), FormatError> {
    let bytes = crate::read_file(path)?;
    let json: FileJson = serde_json::from_slice(&bytes)
        .map_err(|e| FormatError::malformed(path, "a cameras.json with a convention block", e.to_string()))?;
    let records = json
        .views
        .into_iter()
        .map(|v| {
            let bad = |e: dggt_geom::GeomError| FormatError::invalid(path, format!("view {}: {e}", v.name));
            let world_from_camera = WorldFromCamera::from_rows(v.world_from_camera).map_err(bad)?;
            let camera_from_world = dggt_geom::CameraFromWorld::from_rows(v.camera_from_world).map_err(bad)?;
            let error = camera_from_world.max_abs_difference(&world_from_camera.inverse());
            if error > 1e-6 {
                return Err(FormatError::invalid(
                    path,
                    format!("view {}: camera_from_world is not the inverse of world_from_camera ({error:.2e})", v.name),
                ));
            }
            Ok(CameraRecord {
                intrinsics: PinholeIntrinsics::new(v.fx, v.fy, v.cx, v.cy).map_err(bad)?,
                size: ImageSize::new(v.width, v.height).map_err(bad)?,
                name: v.name,
                frame: v.frame,
                camera: v.camera,
                time_s: v.time_s,
                world_from_camera,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((json.convention, records))
}
