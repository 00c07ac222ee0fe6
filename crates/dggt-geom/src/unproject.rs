//! Depth maps to world points.

use glam::DVec3;

use crate::{CameraFromWorld, GeomError, ImageSize, PinholeIntrinsics, PixelConvention};

/// Unprojects a row-major z-depth map to world points: `X_cam = ((u - cx) d / fx, (v - cy) d / fy, d)`,
/// `X_world = Rᵀ (X_cam - t)` for the camera-from-world extrinsic `[R | t]`.
///
/// `convention` says where pixel `(column, row)` lies: the release uses [`PixelConvention::Integer`].
/// Returns one point per pixel in the same order as `depth`; a non-finite depth is an error.
pub fn unproject_depth_map(
    depth: &[f32],
    size: ImageSize,
    intrinsics: &PinholeIntrinsics,
    camera_from_world: &CameraFromWorld,
    convention: PixelConvention,
) -> Result<Vec<DVec3>, GeomError> {
    if depth.len() != size.area() {
        return Err(GeomError::DepthSizeMismatch {
            actual: depth.len(),
            expected: size.area(),
            width: size.width,
            height: size.height,
        });
    }
    intrinsics.validate()?;
    if depth.iter().any(|d| !d.is_finite()) {
        return Err(GeomError::NonFinite { what: "depth map" });
    }
    let world_from_camera = camera_from_world.inverse();
    let width = size.width as usize;
    Ok(depth
        .iter()
        .enumerate()
        .map(|(i, &d)| {
            let pixel = convention.coordinates((i % width) as u32, (i / width) as u32);
            world_from_camera.transform_point(intrinsics.unproject(pixel, d as f64))
        })
        .collect())
}
