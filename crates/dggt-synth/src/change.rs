//! What an edit does to one object of a scene: a rigid [`WorldChange`] of world points, the [`ObjectEdit`]
//! that asks for it (or for the object's removal), and the [`Presence`] the edited scene then draws the object
//! with. The scene places each object by its presence ([`crate::scene`]); a scene's edits are checked and
//! applied by [`crate::edit`].
//!
//! Conventions: the synthetic world is metric with z up, x along the road (the ego's direction of travel at the
//! first frame) and y to the left. A [`WorldChange`] is `x' = Rz(yaw) (x - pivot) + pivot + offset` in those
//! axes, metres, with `yaw` in radians counter-clockwise seen from above (about +z); it is applied after the
//! object's own placement at every time.

use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{Rigid, World};
use serde::{Serialize, Serializer};

use crate::error::{Result, SynthError};
use crate::motion::{CarState, WorldFromObject};
use crate::object_id::ObjectId;

/// A rigid change of world points: `x' = Rz(yaw) (x - pivot) + pivot + offset`.
///
/// World axes (x along the road, y left, z up) and metres; `yaw` in radians, counter-clockwise seen from above
/// (a rotation about the world's up axis, +z, through `pivot`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WorldChange {
    /// Translation applied after the rotation (m).
    #[serde(serialize_with = "vector")]
    pub offset: DVec3,
    /// Rotation about the vertical line through `pivot` (radians, counter-clockwise seen from above).
    pub yaw: f64,
    /// A point of that vertical line (m).
    #[serde(serialize_with = "vector")]
    pub pivot: DVec3,
}

fn vector<S: Serializer>(v: &DVec3, serializer: S) -> std::result::Result<S::Ok, S::Error> {
    v.to_array().serialize(serializer)
}

impl WorldChange {
    /// A pure translation by `offset` (m).
    pub fn translation(offset: DVec3) -> Self {
        Self { offset, yaw: 0.0, pivot: DVec3::ZERO }
    }

    fn rotation(&self) -> DQuat {
        DQuat::from_rotation_z(self.yaw)
    }

    /// The changed world point.
    pub fn apply(&self, point: DVec3) -> DVec3 {
        self.rotate(point - self.pivot) + self.pivot + self.offset
    }

    /// The changed world direction or velocity: the rotation alone.
    pub fn rotate(&self, vector: DVec3) -> DVec3 {
        self.rotation() * vector
    }

    /// Whether every field is finite, as [`SynthScene::edited`](crate::SynthScene::edited) requires.
    pub fn is_finite(&self) -> bool {
        self.offset.is_finite() && self.yaw.is_finite() && self.pivot.is_finite()
    }

    /// The change as a transform of the world into itself; an error when a field is not finite.
    pub fn to_rigid(&self) -> Result<Rigid<World, World>> {
        // Not turned at all unless finite: glam's checked builds assert on a non-finite rotation's products.
        let translation = if self.is_finite() { self.apply(DVec3::ZERO) } else { DVec3::NAN };
        Ok(Rigid::from_rotation_translation(self.rotation(), translation)?)
    }

    /// The placement `pose` followed by this change: object coordinates to changed world points.
    pub fn after(&self, pose: &WorldFromObject) -> Result<WorldFromObject> {
        Ok(self.to_rigid()? * *pose)
    }

    /// A car's motion at one instant followed by this change: the box centre moved, the heading and the
    /// velocity turned by `yaw`, the yaw rate unchanged.
    pub fn after_state(&self, state: &CarState) -> CarState {
        CarState {
            position: self.apply(state.position),
            heading: state.heading + self.yaw,
            velocity: self.rotate(state.velocity),
            yaw_rate: state.yaw_rate,
        }
    }

    /// This change followed by `next`, as one change about this change's pivot.
    pub fn then(&self, next: &WorldChange) -> WorldChange {
        let pivot = self.pivot;
        WorldChange { offset: next.apply(self.apply(pivot)) - pivot, yaw: self.yaw + next.yaw, pivot }
    }

    /// The same change of points written about another `pivot`.
    pub fn about(&self, pivot: DVec3) -> WorldChange {
        WorldChange { offset: self.apply(pivot) - pivot, yaw: self.yaw, pivot }
    }

    /// An error naming `object` and the first field that is not finite.
    pub(crate) fn check(&self, object: ObjectId) -> Result<()> {
        let fields = [
            ("offset", self.offset.is_finite(), self.offset.to_string()),
            ("yaw", self.yaw.is_finite(), self.yaw.to_string()),
            ("pivot", self.pivot.is_finite(), self.pivot.to_string()),
        ];
        match fields.into_iter().find(|(_, finite, _)| !finite) {
            Some((field, _, value)) => Err(SynthError::NonFiniteMove { object, field, value }),
            None => Ok(()),
        }
    }
}

/// One edit of one object of a scene.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectEdit {
    /// The object is drawn nowhere.
    Remove(ObjectId),
    /// The object is drawn at its placement followed by `change`, at every time.
    Move { object: ObjectId, change: WorldChange },
}

impl ObjectEdit {
    /// The object edited.
    pub fn object(&self) -> ObjectId {
        match self {
            Self::Remove(object) | Self::Move { object, .. } => *object,
        }
    }
}

/// Whether and where an edited scene draws an object.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Presence {
    /// Where the generator placed it.
    #[default]
    Generated,
    /// At its generated placement followed by the change, at every time.
    Moved(WorldChange),
    /// Nowhere.
    Removed,
}

impl Presence {
    /// The presence after `edit` of the same object. A removed object stays removed; a second move is composed
    /// with the first.
    pub(crate) fn edited(self, edit: &ObjectEdit) -> Presence {
        match (self, edit) {
            (Presence::Removed, _) | (_, ObjectEdit::Remove(_)) => Presence::Removed,
            (Presence::Moved(earlier), ObjectEdit::Move { change, .. }) => Presence::Moved(earlier.then(change)),
            (Presence::Generated, ObjectEdit::Move { change, .. }) => Presence::Moved(*change),
        }
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_2;

    use super::*;

    fn change() -> WorldChange {
        WorldChange { offset: DVec3::new(1.0, -2.0, 0.5), yaw: 0.7, pivot: DVec3::new(3.0, 4.0, 1.0) }
    }

    #[test]
    fn a_quarter_turn_about_a_pivot_is_counter_clockwise_seen_from_above() {
        let turn = WorldChange { offset: DVec3::ZERO, yaw: FRAC_PI_2, pivot: DVec3::new(1.0, 1.0, 0.0) };
        let moved = turn.apply(DVec3::new(2.0, 1.0, 5.0));
        assert!(moved.abs_diff_eq(DVec3::new(1.0, 2.0, 5.0), 1e-12), "{moved}");
        assert!(turn.rotate(DVec3::X).abs_diff_eq(DVec3::Y, 1e-12));
    }

    #[test]
    fn the_rigid_form_composition_and_pivot_change_agree_with_apply() {
        let (a, b) = (change(), WorldChange { offset: DVec3::new(-0.3, 0.2, 0.0), yaw: -1.9, pivot: DVec3::X });
        let rigid = a.to_rigid().unwrap();
        let composed = a.then(&b);
        let repivoted = a.about(DVec3::new(-7.0, 2.0, 3.0));
        for p in [DVec3::ZERO, DVec3::new(5.0, -1.0, 2.0), DVec3::new(-3.0, 8.0, -4.0)] {
            assert!(rigid.transform_point(p).abs_diff_eq(a.apply(p), 1e-12));
            assert!(composed.apply(p).abs_diff_eq(b.apply(a.apply(p)), 1e-12));
            assert!(repivoted.apply(p).abs_diff_eq(a.apply(p), 1e-12));
        }
    }

    #[test]
    fn a_changed_car_state_moves_its_points_and_their_velocities_together() {
        let state = CarState {
            position: DVec3::new(4.0, 1.0, 0.7),
            heading: 0.4,
            velocity: DVec3::new(5.0, 2.0, 0.0),
            yaw_rate: 0.6,
        };
        let (c, moved) = (change(), change().after_state(&state));
        let local = DVec3::new(1.2, -0.5, 0.3);
        let point = state.world_from_object().transform_point(local);
        let moved_point = moved.world_from_object().transform_point(local);
        assert!(moved_point.abs_diff_eq(c.apply(point), 1e-12));
        assert!(moved.point_velocity(moved_point).abs_diff_eq(c.rotate(state.point_velocity(point)), 1e-12));
        let pose = c.after(&state.world_from_object()).unwrap();
        assert!(pose.max_abs_difference(&moved.world_from_object()) < 1e-12);
    }

    #[test]
    fn a_non_finite_change_is_reported_with_its_field() {
        let bad = WorldChange { yaw: f64::NAN, ..change() };
        assert!(!bad.is_finite());
        assert!(bad.to_rigid().is_err());
        let message = bad.check(7).unwrap_err().to_string();
        assert!(message.contains("object 7") && message.contains("yaw"), "{message}");
    }
}
