//! The camera rig: where each camera sits on the ego vehicle and how it projects.
//!
//! Cameras are defined in OpenCV axes (x right, y down, z forward) and stored in the export as Waymo exports
//! store them: `camera -> ego` in Waymo camera axes (x forward, y left, z up). The rig used for rendering is
//! re-derived from exactly the matrix written to `extrinsics/{cam}.txt`, the way a reader derives it
//! (`ego_from_opencv = ego_from_waymo · M`), so what is rendered and what is read back agree to the last bit.

use dggt_geom::glam::{DMat3, DVec3};
use dggt_geom::{Ego, EgoFromCamera, ImageSize, PinholeIntrinsics, Rigid, WaymoCamera, axes};

use crate::error::Result;

/// Horizontal field of view of every camera, in degrees: neighbouring views (45° apart) overlap by about 33°.
pub const HORIZONTAL_FOV_DEG: f64 = 78.0;

/// Waymo camera names of ids 0, 1, 2.
pub const CAMERA_NAMES: [&str; 3] = ["FRONT", "FRONT_LEFT", "FRONT_RIGHT"];

/// Mounting of camera `id`: yaw left of forward, downward pitch (degrees) and position in the ego frame (m).
const MOUNTS: [(f64, f64, [f64; 3]); 3] =
    [(0.0, 3.0, [1.6, 0.0, 1.6]), (45.0, 3.0, [1.5, 0.3, 1.6]), (-45.0, 3.0, [1.5, -0.3, 1.6])];

/// One camera of the rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigCamera {
    /// Camera id (0 FRONT, 1 FRONT_LEFT, 2 FRONT_RIGHT).
    pub id: usize,
    pub name: &'static str,
    /// The rows written to `extrinsics/{id}.txt`: camera -> ego in Waymo camera axes.
    pub extrinsic_rows: [[f64; 4]; 4],
    /// The same transform as read back from those rows.
    pub ego_from_waymo_camera: Rigid<Ego, WaymoCamera>,
    /// The OpenCV-axes mounting used for rendering: `ego_from_waymo_camera · M`.
    pub ego_from_camera: EgoFromCamera,
}

/// An OpenCV camera looking `yaw` left of the vehicle's forward axis and `pitch_down` below the horizon.
fn opencv_mount(yaw_deg: f64, pitch_down_deg: f64, position: DVec3) -> Result<EgoFromCamera> {
    let (yaw, pitch) = (yaw_deg.to_radians(), pitch_down_deg.to_radians());
    let forward = DVec3::new(yaw.cos() * pitch.cos(), yaw.sin() * pitch.cos(), -pitch.sin());
    let right = DVec3::new(yaw.sin(), -yaw.cos(), 0.0);
    let down = forward.cross(right);
    Ok(Rigid::from_matrix3_translation(DMat3::from_cols(right, down, forward), position)?)
}

/// The first `count` cameras of the rig (`count <= 3`, checked by the configuration).
pub fn build_rig(count: usize) -> Result<Vec<RigCamera>> {
    MOUNTS
        .iter()
        .zip(CAMERA_NAMES)
        .take(count)
        .enumerate()
        .map(|(id, (&(yaw, pitch, position), name))| {
            let mount = opencv_mount(yaw, pitch, DVec3::from_array(position))?;
            let extrinsic_rows = (mount * axes::waymo_camera_from_opencv().inverse()).to_rows();
            let ego_from_waymo_camera = Rigid::from_rows(extrinsic_rows)?;
            let ego_from_camera = axes::ego_from_opencv_camera(&ego_from_waymo_camera);
            Ok(RigCamera { id, name, extrinsic_rows, ego_from_waymo_camera, ego_from_camera })
        })
        .collect()
}

/// Pinhole intrinsics shared by all cameras: square pixels (`fx = fy`) giving [`HORIZONTAL_FOV_DEG`] across the
/// width, principal point at the image centre (image spanning `[0, W] x [0, H]`).
pub fn intrinsics(size: ImageSize) -> Result<PinholeIntrinsics> {
    let (w, h) = (size.width as f64, size.height as f64);
    let f = (w / 2.0) / (HORIZONTAL_FOV_DEG.to_radians() / 2.0).tan();
    Ok(PinholeIntrinsics::new(f, f, w / 2.0, h / 2.0)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mounts_look_where_they_should() {
        let rig = build_rig(3).unwrap();
        let forward = |c: &RigCamera| c.ego_from_camera.transform_vector(DVec3::Z);
        let right = |c: &RigCamera| c.ego_from_camera.transform_vector(DVec3::X);
        assert!(forward(&rig[0]).x > 0.99 && forward(&rig[0]).z < 0.0);
        assert!(right(&rig[0]).abs_diff_eq(-DVec3::Y, 1e-12));
        assert!(forward(&rig[1]).y > 0.6 && forward(&rig[2]).y < -0.6);
        let waymo_forward = rig[1].ego_from_waymo_camera.transform_vector(DVec3::X);
        assert!(waymo_forward.abs_diff_eq(forward(&rig[1]), 1e-12));
        assert!(rig[0].ego_from_camera.translation().abs_diff_eq(DVec3::new(1.6, 0.0, 1.6), 1e-12));
    }
}
