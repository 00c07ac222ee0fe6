//! Lidar sweeps of scene exports (`lidar/{t}.bin`) and their projection to per-camera depth maps.
//!
//! A sweep is raw little-endian float32, one row per return, in one of three layouts ([`LidarFormat`]) that
//! the file size cannot tell apart, so the export variant names it. Points are in the sweep's own frame
//! ([`Sweep`]): the ego frame of that frame for Waymo and Argoverse 2, the lidar sensor's for nuScenes; a
//! [`LidarSweep`] carries the transform into the scene's world.

use std::path::{Path, PathBuf};

use dggt_geom::glam::DVec3;
use dggt_geom::{Camera, ImageSize, PinholeIntrinsics, Rigid, Sweep, World};

use crate::error::{DataError, Result};

/// The row layout of a sweep file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LidarFormat {
    /// drivestudio's Waymo rows: origin (3), point (3), flow (3), flow class, ground, intensity, elongation,
    /// laser id.
    Waymo14,
    /// STORM / DGGT Waymo rows: origin (3), point (3), flow (3), flow class.
    Storm10,
    /// nuScenes and Argoverse 2 rows: x, y, z, intensity.
    XyzIntensity,
}

impl LidarFormat {
    /// Floats per return.
    pub fn stride(self) -> usize {
        match self {
            Self::Waymo14 => 14,
            Self::Storm10 => 10,
            Self::XyzIntensity => 4,
        }
    }

    /// Whether rows carry the ray origin and scene flow (the point comes after the origin).
    fn has_origin_and_flow(self) -> bool {
        !matches!(self, Self::XyzIntensity)
    }
}

/// One frame's sweep file, its layout and where its points sit in the scene.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarSweep {
    pub path: PathBuf,
    pub format: LidarFormat,
    /// The sweep's frame in the scene's world.
    pub world_from_sweep: Rigid<World, Sweep>,
}

impl LidarSweep {
    /// The sweep's points in the scene's world.
    pub fn read_in_world(&self) -> Result<Vec<DVec3>> {
        let points = read_lidar(&self.path, self.format)?;
        Ok(points.iter().map(|p| self.world_from_sweep.transform_point(p.point)).collect())
    }
}

/// One lidar return, in the sweep's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarPoint {
    /// Sensor origin of the ray (zero where the format has none).
    pub origin: DVec3,
    /// The return.
    pub point: DVec3,
    /// Scene flow of the return in m/s (zero where the format has none).
    pub flow: DVec3,
}

/// Reads a lidar sweep, checking that it holds whole, finite points.
pub fn read_lidar(path: &Path, format: LidarFormat) -> Result<Vec<LidarPoint>> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let stride = format.stride();
    let point_bytes = stride * 4;
    if bytes.len() % point_bytes != 0 {
        return Err(DataError::malformed(
            path,
            format!("a multiple of {point_bytes} bytes (float32 x {stride} per point)"),
            format!("{} bytes", bytes.len()),
        ));
    }
    let geometric = if format.has_origin_and_flow() { 9 } else { 3 };
    bytes
        .chunks_exact(point_bytes)
        .enumerate()
        .map(|(i, chunk)| {
            let v: Vec<f64> = chunk[..geometric * 4]
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64)
                .collect();
            if v.iter().any(|x| !x.is_finite()) {
                return Err(DataError::malformed(
                    path,
                    "finite coordinates",
                    format!("a non-finite value in point {i}"),
                ));
            }
            Ok(match format.has_origin_and_flow() {
                true => LidarPoint {
                    origin: DVec3::new(v[0], v[1], v[2]),
                    point: DVec3::new(v[3], v[4], v[5]),
                    flow: DVec3::new(v[6], v[7], v[8]),
                },
                false => LidarPoint { origin: DVec3::ZERO, point: DVec3::new(v[0], v[1], v[2]), flow: DVec3::ZERO },
            })
        })
        .collect()
}

/// Projects world points into a camera as a sparse z-depth map (row-major, 0 = no return). A point falls in
/// the pixel `(floor u, floor v)` of the image `[0, W] x [0, H]`; where several do, the nearest wins.
pub fn project_to_depth(
    points_in_world: &[DVec3],
    camera_from_world: &Rigid<Camera, World>,
    intrinsics: &PinholeIntrinsics,
    size: ImageSize,
) -> Vec<f32> {
    let mut depth = vec![0f32; size.area()];
    for &p in points_in_world {
        let in_camera = camera_from_world.transform_point(p);
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

/// Writes a lidar sweep in `format` (the synthetic scenes and tests); columns the points do not carry (flow
/// class, ground, intensity, elongation, laser id) are zero.
pub fn write_lidar(path: &Path, format: LidarFormat, points: &[LidarPoint]) -> Result<()> {
    let stride = format.stride();
    let mut bytes = Vec::with_capacity(points.len() * stride * 4);
    for p in points {
        let values: Vec<f64> = match format.has_origin_and_flow() {
            true => [p.origin.to_array(), p.point.to_array(), p.flow.to_array()].concat(),
            false => p.point.to_array().to_vec(),
        };
        for v in values.iter().copied().chain(std::iter::repeat(0.0)).take(stride) {
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
        let mount = Rigid::<World, Camera>::from_rotation_translation(
            DQuat::from_mat3(&dggt_geom::axes::waymo_camera_from_opencv().rotation_matrix()),
            DVec3::new(0.0, 0.0, 1.5),
        )
        .unwrap();
        let point = |x, y, z| LidarPoint { origin: DVec3::ZERO, point: DVec3::new(x, y, z), flow: DVec3::ZERO };
        let points = [point(10.0, 0.0, 1.5), point(12.0, 0.0, 1.5), point(-5.0, 0.0, 1.5), point(10.0, 1.0, 1.0)];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("000.bin");
        write_lidar(&path, LidarFormat::Waymo14, &points).unwrap();
        let back = read_lidar(&path, LidarFormat::Waymo14).unwrap();
        assert_eq!(back, points);
        let in_world: Vec<DVec3> = back.iter().map(|p| p.point).collect();
        let depth = project_to_depth(&in_world, &mount.inverse(), &k, size);
        assert_eq!(depth[24 * 64 + 32], 10.0, "nearest of two returns on the optical axis");
        // Left (+y) is image left, down (-z) is image down: u = 32 - 50 * 1 / 10 = 27, v = 24 + 50 * 0.5 / 10 = 26.5.
        assert_eq!(depth[26 * 64 + 27], 10.0);
        assert_eq!(depth.iter().filter(|&&d| d > 0.0).count(), 2, "the point behind the camera is dropped");
        std::fs::write(&path, [0u8; 13]).unwrap();
        assert!(read_lidar(&path, LidarFormat::Waymo14).unwrap_err().to_string().contains("000.bin"));
    }

    #[test]
    fn every_format_round_trips_the_points_it_carries() {
        let point = LidarPoint { origin: DVec3::new(0.0, 0.0, 2.0), point: DVec3::new(5.0, -1.0, 0.5), flow: DVec3::X };
        let dir = tempfile::tempdir().unwrap();
        for format in [LidarFormat::Waymo14, LidarFormat::Storm10, LidarFormat::XyzIntensity] {
            let path = dir.path().join("sweep.bin");
            write_lidar(&path, format, &[point, point]).unwrap();
            assert_eq!(std::fs::metadata(&path).unwrap().len() as usize, 2 * 4 * format.stride());
            let back = read_lidar(&path, format).unwrap();
            assert_eq!(back.len(), 2);
            assert_eq!(back[1].point, point.point, "{format:?}");
            let expected_flow = if format == LidarFormat::XyzIntensity { DVec3::ZERO } else { DVec3::X };
            assert_eq!(back[1].flow, expected_flow, "{format:?}");
        }
    }
}
