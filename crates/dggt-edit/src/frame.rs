//! The world's up axis, about which yaws turn. A reconstruction's world is whatever frame its cameras are in
//! (the first input camera's, OpenCV axes, when they were predicted), so "up" is taken from the cameras: the
//! direction opposite to the first input camera's image rows (`-y` of its camera axes), which is the sky's side
//! for a camera mounted level on a vehicle.

use dggt_geom::PosedCamera;
use dggt_geom::glam::{DQuat, DVec3};

/// The unit up direction of a reconstruction's world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldUp(DVec3);

impl WorldUp {
    /// The up of the world `camera` is posed in: its `-y` axis in world axes.
    pub fn of_camera(camera: &PosedCamera) -> Self {
        Self(camera.world_from_camera.transform_vector(DVec3::NEG_Y).normalize())
    }

    pub fn direction(self) -> DVec3 {
        self.0
    }

    /// The turn by `degrees` counter-clockwise seen from above (right-handed about up).
    pub fn yaw(self, degrees: f64) -> DQuat {
        DQuat::from_axis_angle(self.0, degrees.to_radians())
    }

    /// The shortest turn taking `from`'s up onto this one (for an object carried between two worlds).
    pub fn turn_from(self, from: WorldUp) -> DQuat {
        DQuat::from_rotation_arc(from.0, self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::{PinholeIntrinsics, WorldFromCamera};

    #[test]
    fn a_level_opencv_camera_has_minus_y_up_and_yaw_turns_counter_clockwise_from_above() {
        let camera = PosedCamera {
            world_from_camera: WorldFromCamera::from_rotation_translation(DQuat::IDENTITY, DVec3::ONE).unwrap(),
            intrinsics: PinholeIntrinsics::new(10.0, 10.0, 5.0, 5.0).unwrap(),
        };
        let up = WorldUp::of_camera(&camera);
        assert!(up.direction().abs_diff_eq(DVec3::NEG_Y, 1e-12));
        // Right-handed about -y (counter-clockwise seen from above): a quarter turn takes right (+x) to forward.
        let turned = up.yaw(90.0) * DVec3::X;
        assert!(turned.abs_diff_eq(DVec3::Z, 1e-12), "{turned}");
        let z_up = WorldUp(DVec3::Z);
        assert!((z_up.yaw(90.0) * DVec3::X).abs_diff_eq(DVec3::Y, 1e-12), "x turns to y about +z");
        assert!((up.turn_from(z_up) * DVec3::Z).abs_diff_eq(DVec3::NEG_Y, 1e-12));
    }
}
