//! Scene flow of lidar points from tracked 3D boxes: a point inside an annotated box moves with the box's rigid
//! motion to a neighbouring frame; a point outside every box is static.
//!
//! Conventions: points, boxes and flow are in the log's world ([`LogWorld`], the world of `ego_pose/` and of
//! `instances/`); box axes have their origin at the box centre, x along the length, y along the width, z up
//! ([`ObjectBox`]); flow is a velocity in metres per second. For a point `p` inside box `b` at frame `t` whose
//! object (the same id) is also annotated at the neighbouring frame `n`:
//!
//! `p' = world_from_box_b(n) · box_b_from_world(t) · p`, flow `= (p' − p) / (time(n) − time(t))`.
//!
//! The neighbour is the next frame; where the object is not annotated there (its track ends, or `t` is the last
//! frame), the previous frame (a backward difference: the division by the negative time step keeps the sign of
//! the motion). An object annotated at neither neighbour (a box seen in one frame only) has no known motion:
//! its points get zero flow, as static points do. A point inside several boxes takes the first box of its
//! frame's list. Boxes are exact (no margin): returns just outside a box are static.

use dggt_geom::glam::DVec3;
use dggt_geom::{Ego, LogWorld, Rigid};

use crate::boxes::{AnnotatedBox, ObjectBox};

/// Why a frame's box flow cannot be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoxFlowError {
    /// A box's size is not three positive finite lengths.
    #[error("object `{id}`: expected a box size of three positive finite lengths, found {size:?}")]
    Size { id: String, size: [f64; 3] },
    /// Two frames' times are equal or not finite, so no velocity follows from their displacement.
    #[error("expected frame times that differ and are finite, found {now} s and a neighbour at {neighbour} s")]
    TimeStep { now: f64, neighbour: f64 },
}

/// One annotated box in the log's world.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldBox {
    /// The dataset's object id, stable across the log.
    pub id: String,
    pub world_from_box: Rigid<LogWorld, ObjectBox>,
    /// Length, width, height in metres.
    pub size: DVec3,
}

impl WorldBox {
    /// An ego-frame box moved into the world by the frame's ego pose.
    pub fn of(object: &AnnotatedBox, world_from_ego: &Rigid<LogWorld, Ego>) -> Self {
        Self { id: object.id.clone(), world_from_box: *world_from_ego * object.ego_from_box, size: object.size }
    }

    /// Whether the world point lies inside the box (its faces included).
    pub fn contains(&self, point_in_world: DVec3) -> bool {
        let in_box = self.world_from_box.inverse().transform_point(point_in_world);
        inside_box(self.size, in_box)
    }

    fn check(&self) -> Result<(), BoxFlowError> {
        if self.size.is_finite() && self.size.min_element() > 0.0 {
            Ok(())
        } else {
            Err(BoxFlowError::Size { id: self.id.clone(), size: self.size.to_array() })
        }
    }
}

/// Whether a point in box coordinates (centre origin) lies within the box of `size` (length, width, height).
pub fn inside_box(size: DVec3, point_in_box: DVec3) -> bool {
    let half = size * 0.5;
    point_in_box.abs().cmple(half).all()
}

/// The boxes of one frame and the frame's time.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameBoxes {
    /// Seconds on the log's clock (any origin shared by the frames).
    pub time_s: f64,
    pub boxes: Vec<WorldBox>,
}

/// A box's rigid motion from its frame to a neighbouring frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxMotion {
    /// `world_from_box(n) · box_from_world(t)`: where a point of the box at `t` is at `n`.
    pub neighbour_from_now: Rigid<LogWorld, LogWorld>,
    /// `time(n) − time(t)`, negative for the previous frame.
    pub seconds: f64,
}

impl BoxMotion {
    /// The motion of a box posed `now` at time `now_s` and `neighbour` at `neighbour_s`.
    pub fn between(
        now: &Rigid<LogWorld, ObjectBox>,
        now_s: f64,
        neighbour: &Rigid<LogWorld, ObjectBox>,
        neighbour_s: f64,
    ) -> Result<Self, BoxFlowError> {
        let seconds = neighbour_s - now_s;
        if !(seconds.is_finite() && seconds != 0.0) {
            return Err(BoxFlowError::TimeStep { now: now_s, neighbour: neighbour_s });
        }
        Ok(Self { neighbour_from_now: *neighbour * now.inverse(), seconds })
    }

    /// The velocity (m/s, world axes) of a world point moving with the box.
    pub fn velocity(&self, point_in_world: DVec3) -> DVec3 {
        (self.neighbour_from_now.transform_point(point_in_world) - point_in_world) / self.seconds
    }
}

/// A box of the frame with its motion, `None` when its object is annotated at neither neighbour.
#[derive(Debug, Clone)]
struct MovingBox {
    box_from_world: Rigid<ObjectBox, LogWorld>,
    size: DVec3,
    /// Half the box diagonal: points farther than this from the centre are outside.
    radius: f64,
    centre: DVec3,
    motion: Option<BoxMotion>,
}

/// The flow field of one frame: every box with its motion to a neighbouring frame.
#[derive(Debug, Clone)]
pub struct FrameFlow {
    boxes: Vec<MovingBox>,
}

impl FrameFlow {
    /// The flow of frame `now`, with the neighbours `next` and `previous` when the log has them.
    pub fn new(
        now: &FrameBoxes,
        next: Option<&FrameBoxes>,
        previous: Option<&FrameBoxes>,
    ) -> Result<Self, BoxFlowError> {
        let find = |frame: Option<&FrameBoxes>, id: &str| {
            frame.and_then(|f| f.boxes.iter().find(|b| b.id == id).map(|b| (b.world_from_box, f.time_s)))
        };
        let boxes = now
            .boxes
            .iter()
            .map(|object| {
                object.check()?;
                let neighbour = find(next, &object.id).or_else(|| find(previous, &object.id));
                let motion = neighbour
                    .map(|(pose, time_s)| BoxMotion::between(&object.world_from_box, now.time_s, &pose, time_s))
                    .transpose()?;
                Ok(MovingBox {
                    box_from_world: object.world_from_box.inverse(),
                    size: object.size,
                    radius: object.size.length() * 0.5,
                    centre: object.world_from_box.translation(),
                    motion,
                })
            })
            .collect::<Result<_, BoxFlowError>>()?;
        Ok(Self { boxes })
    }

    /// The velocity (m/s, world axes) of a world point: its box's motion, or zero outside every box and inside
    /// a box without a neighbour.
    pub fn velocity(&self, point_in_world: DVec3) -> DVec3 {
        let inside = self.boxes.iter().find(|b| {
            point_in_world.distance_squared(b.centre) <= b.radius * b.radius
                && inside_box(b.size, b.box_from_world.transform_point(point_in_world))
        });
        inside.and_then(|b| b.motion).map_or(DVec3::ZERO, |motion| motion.velocity(point_in_world))
    }

    /// Whether any box of the frame has a motion.
    pub fn has_motion(&self) -> bool {
        self.boxes.iter().any(|b| b.motion.is_some())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::glam::DQuat;

    fn pose(yaw: f64, centre: DVec3) -> Rigid<LogWorld, ObjectBox> {
        Rigid::from_rotation_translation(DQuat::from_rotation_z(yaw), centre).unwrap()
    }

    fn frame(time_s: f64, boxes: &[(&str, Rigid<LogWorld, ObjectBox>)]) -> FrameBoxes {
        let boxes = boxes
            .iter()
            .map(|(id, pose)| WorldBox { id: id.to_string(), world_from_box: *pose, size: DVec3::new(4.0, 2.0, 1.5) })
            .collect();
        FrameBoxes { time_s, boxes }
    }

    #[test]
    fn a_point_is_inside_a_box_up_to_its_faces_along_its_own_axes() {
        let size = DVec3::new(4.0, 2.0, 1.5);
        assert!(inside_box(size, DVec3::new(2.0, -1.0, 0.75)), "a corner");
        assert!(!inside_box(size, DVec3::new(2.01, 0.0, 0.0)), "beyond the front");
        assert!(!inside_box(size, DVec3::new(0.0, 1.01, 0.0)), "beyond the side");
        assert!(!inside_box(size, DVec3::new(0.0, 0.0, -0.76)), "below");
        // Turned a quarter left about its centre (10, 0, 0): its length lies along world y.
        let turned = WorldBox {
            id: "a".into(),
            world_from_box: pose(std::f64::consts::FRAC_PI_2, DVec3::new(10.0, 0.0, 0.0)),
            size,
        };
        assert!(turned.contains(DVec3::new(10.9, 1.9, 0.0)));
        assert!(!turned.contains(DVec3::new(11.5, 0.0, 0.0)), "1.5 m along world x is across its 2 m width");
    }

    #[test]
    fn a_point_on_a_turning_box_moves_by_the_hand_computed_displacement() {
        // The box turns 90° left about its centre and its centre moves 3 m along world x, in 0.1 s.
        let (c0, c1) = (DVec3::new(10.0, 5.0, 1.0), DVec3::new(13.0, 5.0, 1.0));
        let now = frame(2.0, &[("car", pose(0.0, c0))]);
        let next = frame(2.1, &[("car", pose(std::f64::consts::FRAC_PI_2, c1))]);
        let flow = FrameFlow::new(&now, Some(&next), None).unwrap();
        // The point 1.5 m ahead of the centre and 0.5 m to its left, 0.25 m up: box coordinates (1.5, 0.5, 0.25).
        // A quarter turn left takes (1.5, 0.5) to (-0.5, 1.5), so the point lands at c1 + (-0.5, 1.5, 0.25) =
        // (12.5, 6.5, 1.25) from (11.5, 5.5, 1.25): a displacement (1, 1, 0) in 0.1 s, 10 m/s along x and y.
        let p = DVec3::new(11.5, 5.5, 1.25);
        let velocity = flow.velocity(p);
        assert!(velocity.abs_diff_eq(DVec3::new(10.0, 10.0, 0.0), 1e-9), "{velocity}");
        // The centre moves by the translation alone: 3 m in 0.1 s.
        assert!(flow.velocity(c0).abs_diff_eq(DVec3::new(30.0, 0.0, 0.0), 1e-9));
        // Outside every box: static.
        assert_eq!(flow.velocity(DVec3::new(20.0, 5.0, 1.0)), DVec3::ZERO);
        assert_eq!(flow.velocity(DVec3::new(11.5, 5.5, 3.0)), DVec3::ZERO, "above the box");
    }

    #[test]
    fn the_last_frame_looks_back_and_a_box_seen_once_has_no_flow() {
        let previous = frame(0.0, &[("car", pose(0.0, DVec3::new(0.0, 0.0, 0.0)))]);
        let now = frame(
            0.5,
            &[("car", pose(0.0, DVec3::new(1.0, 0.0, 0.0))), ("once", pose(0.0, DVec3::new(0.0, 10.0, 0.0)))],
        );
        let flow = FrameFlow::new(&now, None, Some(&previous)).unwrap();
        // Backward difference: moved +1 m along x over the last 0.5 s, so +2 m/s (not -2).
        assert!(flow.velocity(DVec3::new(1.5, 0.0, 0.0)).abs_diff_eq(DVec3::new(2.0, 0.0, 0.0), 1e-12));
        assert_eq!(flow.velocity(DVec3::new(0.0, 10.0, 0.0)), DVec3::ZERO, "annotated in this frame only");
        // A frame without neighbours has boxes but no motion.
        let alone = FrameFlow::new(&now, None, None).unwrap();
        assert!(!alone.has_motion());
        assert_eq!(alone.velocity(DVec3::new(1.5, 0.0, 0.0)), DVec3::ZERO);
    }

    #[test]
    fn a_box_without_a_size_and_frames_at_one_time_are_errors() {
        let mut now = frame(0.0, &[("car", pose(0.0, DVec3::ZERO))]);
        let next = frame(0.1, &[("car", pose(0.0, DVec3::X))]);
        now.boxes[0].size.y = f64::NAN;
        let error = FrameFlow::new(&now, Some(&next), None).unwrap_err();
        assert!(matches!(&error, BoxFlowError::Size { id, .. } if id == "car"), "{error}");
        now.boxes[0].size.y = 2.0;
        let same_time = frame(0.0, &[("car", pose(0.0, DVec3::X))]);
        let error = FrameFlow::new(&now, Some(&same_time), None).unwrap_err();
        assert!(error.to_string().contains("frame times that differ"), "{error}");
    }
}
