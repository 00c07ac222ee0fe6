//! Lidar sweeps of scene exports (`lidar/{t}.bin`) and their projection to per-camera depth maps.
//!
//! A sweep is raw little-endian float32, `N x 14` per point: ray origin (3), point (3), scene flow (3),
//! flow class, ground label, intensity, elongation, laser id. Origins and points are in the ego frame of that
//! frame (forward-left-up), as Waymo's range images are decoded.

use std::path::Path;

use dggt_geom::glam::DVec3;
use dggt_geom::{EgoFromCamera, ImageSize, PinholeIntrinsics};

use crate::error::{DataError, Result};

/// Floats per lidar point in the export layout.
pub const LIDAR_POINT_STRIDE: usize = 14;

/// One lidar return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarPoint {
    /// Sensor origin of the ray, ego frame.
    pub origin: DVec3,
    /// The return, ego frame.
    pub point: DVec3,
    /// Scene flow of the return.
    pub flow: DVec3,
}

/// Reads a lidar sweep, checking that it holds whole, finite points.
pub fn read_lidar(path: &Path) -> Result<Vec<LidarPoint>> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let point_bytes = LIDAR_POINT_STRIDE * 4;
    if bytes.len() % point_bytes != 0 {
        return Err(DataError::malformed(
            path,
            format!("a multiple of {point_bytes} bytes (float32 x {LIDAR_POINT_STRIDE} per point)"),
            format!("{} bytes", bytes.len()),
        ));
    }
    bytes
        .chunks_exact(point_bytes)
        .enumerate()
        .map(|(i, chunk)| {
            let v: Vec<f64> =
                chunk.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64).collect();
            if v[..9].iter().any(|x| !x.is_finite()) {
                return Err(DataError::malformed(
                    path,
                    "finite coordinates",
                    format!("a non-finite value in point {i}"),
                ));
            }
            Ok(LidarPoint {
                origin: DVec3::new(v[0], v[1], v[2]),
                point: DVec3::new(v[3], v[4], v[5]),
                flow: DVec3::new(v[6], v[7], v[8]),
            })
        })
        .collect()
}

/// Projects lidar returns into a camera as a sparse z-depth map (row-major, 0 = no return). Where several
/// returns fall into one pixel the nearest wins.
pub fn project_to_depth(
    points: &[LidarPoint],
    ego_from_camera: &EgoFromCamera,
    intrinsics: &PinholeIntrinsics,
    size: ImageSize,
) -> Vec<f32> {
    let camera_from_ego = ego_from_camera.inverse();
    let mut depth = vec![0f32; size.area()];
    for p in points {
        let in_camera = camera_from_ego.transform_point(p.point);
        let Some(pixel) = intrinsics.project(in_camera) else { continue };
        if pixel.x < 0.0 || pixel.y < 0.0 || pixel.x >= size.width as f64 || pixel.y >= size.height as f64 {
            continue;
        }
        let i = pixel.y as usize * size.width as usize + pixel.x as usize;
        let z = in_camera.z as f32;
        if depth[i] == 0.0 || z < depth[i] {
            depth[i] = z;
        }
    }
    depth
}

/// Writes a lidar sweep in the export layout (used by the synthetic scenes and tests).
pub fn write_lidar(path: &Path, points: &[LidarPoint]) -> Result<()> {
    let mut bytes = Vec::with_capacity(points.len() * LIDAR_POINT_STRIDE * 4);
    for p in points {
        let values = [p.origin.to_array(), p.point.to_array(), p.flow.to_array()].concat();
        for v in values.iter().copied().chain([0.0; LIDAR_POINT_STRIDE - 9]) {
            bytes.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    crate::io::write_atomically(path, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::glam::DQuat;

    #[test]
    fn projection_puts_points_where_the_camera_sees_them() {
        let k = PinholeIntrinsics::new(50.0, 50.0, 32.0, 24.0).unwrap();
        let size = ImageSize::new(64, 48).unwrap();
        // A forward-looking camera 1.5 m up: OpenCV z = ego x.
        let mount = EgoFromCamera::from_rotation_translation(
            DQuat::from_mat3(&dggt_geom::axes::waymo_camera_from_opencv().rotation_matrix()),
            DVec3::new(0.0, 0.0, 1.5),
        )
        .unwrap();
        let point = |x, y, z| LidarPoint { origin: DVec3::ZERO, point: DVec3::new(x, y, z), flow: DVec3::ZERO };
        let points = [point(10.0, 0.0, 1.5), point(12.0, 0.0, 1.5), point(-5.0, 0.0, 1.5), point(10.0, 1.0, 1.0)];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000.bin");
        write_lidar(&path, &points).unwrap();
        let back = read_lidar(&path).unwrap();
        assert_eq!(back.len(), 4);
        let depth = project_to_depth(&back, &mount, &k, size);
        assert_eq!(depth[24 * 64 + 32], 10.0, "nearest of two returns on the optical axis");
        // Left (+y) is image left, down (-z) is image down: u = 32 - 50 * 1 / 10 = 27, v = 24 + 50 * 0.5 / 10 = 26.5.
        assert_eq!(depth[26 * 64 + 27], 10.0);
        assert_eq!(depth.iter().filter(|&&d| d > 0.0).count(), 2, "the point behind the camera is dropped");
        std::fs::write(&path, [0u8; 13]).unwrap();
        assert!(read_lidar(&path).unwrap_err().to_string().contains("000.bin"));
    }
}
