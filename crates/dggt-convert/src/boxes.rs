//! Annotated 3D boxes: their pose on the ego vehicle, size, class and horizontal speed, and their corners.
//!
//! Box axes: origin at the box centre, x along its length (forward), y along its width (left), z up.

use dggt_geom::frames::Frame;
use dggt_geom::glam::DVec3;
use dggt_geom::{Ego, Rigid};

/// The frame of an annotated object's box (centre origin, x forward, y left, z up).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectBox;

impl Frame for ObjectBox {
    const NAME: &'static str = "object box";
}

/// The classes that dynamic masks and `instances/` keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ObjectClass {
    Vehicle,
    /// Pedestrians and cyclists (and, in other datasets, riders and animals).
    Human,
}

/// One annotated box in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct AnnotatedBox {
    /// The dataset's object id, stable across the log.
    pub id: String,
    /// The dataset's class name, written to `instances_info.json`.
    pub class_name: &'static str,
    pub class: ObjectClass,
    pub ego_from_box: Rigid<Ego, ObjectBox>,
    /// Length, width, height in metres.
    pub size: DVec3,
    /// Horizontal speed in m/s.
    pub speed: f64,
    /// Whether the lidar saw the object (boxes without points are left out of masks).
    pub has_points: bool,
}

impl AnnotatedBox {
    /// The 8 corners in the ego frame.
    pub fn corners_in_ego(&self) -> [DVec3; 8] {
        let half = self.size * 0.5;
        std::array::from_fn(|i| {
            let sign = |bit: usize| if i & (1 << bit) == 0 { -1.0 } else { 1.0 };
            let local = DVec3::new(sign(0) * half.x, sign(1) * half.y, sign(2) * half.z);
            self.ego_from_box.transform_point(local)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::glam::DQuat;

    #[test]
    fn corners_follow_the_heading() {
        let quarter_turn = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let object = AnnotatedBox {
            id: "a".into(),
            class_name: "Vehicle",
            class: ObjectClass::Vehicle,
            ego_from_box: Rigid::from_rotation_translation(quarter_turn, DVec3::new(10.0, 0.0, 1.0)).unwrap(),
            size: DVec3::new(4.0, 2.0, 1.5),
            speed: 0.0,
            has_points: true,
        };
        let corners = object.corners_in_ego();
        let (min, max) =
            corners.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &c| (lo.min(c), hi.max(c)));
        // Turned a quarter left, the 4 m length lies along ego y.
        assert!(min.abs_diff_eq(DVec3::new(9.0, -2.0, 0.25), 1e-12), "{min}");
        assert!(max.abs_diff_eq(DVec3::new(11.0, 2.0, 1.75), 1e-12), "{max}");
    }
}
