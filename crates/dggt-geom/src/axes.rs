//! Axis conventions of sensors: Waymo's forward-left-up cameras to OpenCV cameras.
//!
//! A Waymo camera looks along its +x axis with +y left and +z up; an OpenCV camera looks along +z with +x right
//! and +y down. Scene exports store `camera -> ego` in Waymo axes; the conversion appends the fixed change of axes
//! `camera_to_ego_opencv = camera_to_ego · M` with `M = [[0,0,1],[-1,0,0],[0,-1,0]]`.

use glam::{DMat3, DVec3};

use crate::frames::{Camera, Ego, WaymoCamera};
use crate::rigid::Rigid;

/// The fixed change of axes `M`: OpenCV camera coordinates into Waymo camera coordinates
/// (`x_waymo = z_cv`, `y_waymo = -x_cv`, `z_waymo = -y_cv`).
pub fn waymo_camera_from_opencv() -> Rigid<WaymoCamera, Camera> {
    let m = DMat3::from_cols(DVec3::new(0.0, -1.0, 0.0), DVec3::new(0.0, 0.0, -1.0), DVec3::new(1.0, 0.0, 0.0));
    Rigid::from_matrix3_translation(m, DVec3::ZERO).expect("the axis change is a rotation")
}

/// A Waymo camera's mounting (`camera -> ego`, Waymo axes) as an OpenCV camera's mounting.
pub fn ego_from_opencv_camera(ego_from_waymo_camera: &Rigid<Ego, WaymoCamera>) -> Rigid<Ego, Camera> {
    *ego_from_waymo_camera * waymo_camera_from_opencv()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn optical_axis_becomes_forward_and_image_down_becomes_down() {
        let m = waymo_camera_from_opencv();
        assert!(m.transform_vector(DVec3::Z).abs_diff_eq(DVec3::X, 1e-15), "optical axis is forward");
        assert!(m.transform_vector(DVec3::X).abs_diff_eq(-DVec3::Y, 1e-15), "image right is vehicle right (-y)");
        assert!(m.transform_vector(DVec3::Y).abs_diff_eq(-DVec3::Z, 1e-15), "image down is down (-z)");
        let expected = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];
        let rows = m.to_rows();
        for (row, want) in rows.iter().zip(expected) {
            for (v, w) in row.iter().zip(want) {
                assert!((v - w).abs() < 1e-15, "{rows:?}");
            }
        }
    }
}
