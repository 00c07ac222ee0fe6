//! nerfstudio's `transforms.json`.
//!
//! Convention (nerfstudio's): `transform_matrix` is camera-to-world in OpenGL camera axes (x right, y up,
//! z back), i.e. the OpenCV pose with its y and z columns negated; intrinsics `fl_x fl_y cx cy` in pixels of
//! `w x h` images, given per frame because predicted intrinsics differ between frames. `file_path` is relative
//! to the file's folder.

use std::path::Path;

use dggt_geom::{ImageSize, PinholeIntrinsics, WorldFromCamera};
use serde::{Deserialize, Serialize};

use crate::FormatError;

/// One frame as this module takes and returns it: an OpenCV-axes pose, converted at the file boundary.
#[derive(Debug, Clone, PartialEq)]
pub struct NerfstudioFrame {
    pub file_path: String,
    pub size: ImageSize,
    pub intrinsics: PinholeIntrinsics,
    /// Camera-to-world, OpenCV axes.
    pub world_from_camera: WorldFromCamera,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct FrameJson {
    file_path: String,
    transform_matrix: [[f64; 4]; 4],
    fl_x: f64,
    fl_y: f64,
    cx: f64,
    cy: f64,
    w: u32,
    h: u32,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct TransformsJson {
    camera_model: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    convention: Option<String>,
    frames: Vec<FrameJson>,
}

const CONVENTION: &str =
    "transform_matrix: camera-to-world, OpenGL camera axes (x right, y up, z back); intrinsics in pixels";

/// OpenCV pose to OpenGL: negate the camera's y and z axes (columns 1 and 2 of the rotation).
pub fn opengl_matrix(world_from_camera: &WorldFromCamera) -> [[f64; 4]; 4] {
    let mut rows = world_from_camera.to_rows();
    for row in rows.iter_mut().take(3) {
        row[1] = -row[1];
        row[2] = -row[2];
    }
    rows
}

/// The inverse of [`opengl_matrix`].
pub fn from_opengl_matrix(mut rows: [[f64; 4]; 4]) -> Result<WorldFromCamera, dggt_geom::GeomError> {
    for row in rows.iter_mut().take(3) {
        row[1] = -row[1];
        row[2] = -row[2];
    }
    WorldFromCamera::from_rows(rows)
}

/// Writes `transforms.json`.
pub fn write_transforms(path: &Path, frames: &[NerfstudioFrame]) -> Result<(), FormatError> {
    let json = TransformsJson {
        camera_model: "PINHOLE".into(),
        convention: Some(CONVENTION.into()),
        frames: frames
            .iter()
            .map(|f| FrameJson {
                file_path: f.file_path.clone(),
                transform_matrix: opengl_matrix(&f.world_from_camera),
                fl_x: f.intrinsics.fx,
                fl_y: f.intrinsics.fy,
                cx: f.intrinsics.cx,
                cy: f.intrinsics.cy,
                w: f.size.width,
                h: f.size.height,
            })
            .collect(),
    };
    let text = serde_json::to_string_pretty(&json).map_err(|e| FormatError::invalid(path, e.to_string()))?;
    crate::write_file(path, text.as_bytes())
}

/// Reads a `transforms.json` written by [`write_transforms`] (per-frame intrinsics).
pub fn read_transforms(path: &Path) -> Result<Vec<NerfstudioFrame>, FormatError> {
    let bytes = crate::read_file(path)?;
    let json: TransformsJson = serde_json::from_slice(&bytes)
        .map_err(|e| FormatError::malformed(path, "a transforms.json with per-frame intrinsics", e.to_string()))?;
    json.frames
        .into_iter()
        .enumerate()
        .map(|(i, f)| {
            let bad = |e: dggt_geom::GeomError| FormatError::invalid(path, format!("frame {i}: {e}"));
            Ok(NerfstudioFrame {
                world_from_camera: from_opengl_matrix(f.transform_matrix).map_err(bad)?,
                intrinsics: PinholeIntrinsics::new(f.fl_x, f.fl_y, f.cx, f.cy).map_err(bad)?,
                size: ImageSize::new(f.w, f.h).map_err(bad)?,
                file_path: f.file_path,
            })
        })
        .collect()
}
