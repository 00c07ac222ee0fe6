//! Edited copies of a scene: objects removed, or moved by a rigid change, as ground truth for scene editing.
//!
//! Scene editing (removing or moving an object of a reconstruction) is checked against renders of the same scene
//! without the object, or with the object where the edit puts it. [`SynthScene::edited`] gives that scene: a
//! removed object is placed nowhere, so no camera ray, lidar beam, mask or instance list meets it; a moved object
//! is drawn at its moved pose at every time, and its velocity (the scene flow) is the moved object's. Shading
//! has no shadows, so no other surface changes.
//!
//! Conventions: the synthetic world is metric with z up, x along the road (the ego's direction of travel at the
//! first frame) and y to the left. A [`WorldChange`] is `x' = Rz(yaw) (x - pivot) + pivot + offset` in those
//! axes, metres, with `yaw` in radians counter-clockwise seen from above (about +z); it is applied after the
//! object's own placement at every time. Object ids never change: an edited object keeps its index in
//! [`SynthScene::objects`], and a removed one stays listed there with [`Presence::Removed`].

use std::collections::BTreeMap;
use std::collections::btree_map::Entry;
use std::fmt;
use std::str::FromStr;

use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{Rigid, World};
use serde::{Serialize, Serializer};

use crate::config::SynthConfig;
use crate::error::{Result, SynthError};
use crate::motion::{CarState, WorldFromObject};
use crate::scene::{ObjectId, SceneObject, SynthScene};

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

    /// Whether every field is finite, as [`SynthScene::edited`] requires.
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
    fn check(&self, object: ObjectId) -> Result<()> {
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
    fn edited(self, edit: &ObjectEdit) -> Presence {
        match (self, edit) {
            (Presence::Removed, _) | (_, ObjectEdit::Remove(_)) => Presence::Removed,
            (Presence::Moved(earlier), ObjectEdit::Move { change, .. }) => Presence::Moved(earlier.then(change)),
            (Presence::Generated, ObjectEdit::Move { change, .. }) => Presence::Moved(*change),
        }
    }
}

impl SynthScene {
    /// A copy of the scene with `edits` applied. Each object may be named by one edit (repeating the very same
    /// edit counts once); an object moved by an earlier call is moved further, its changes composed.
    ///
    /// Errors, naming the object: an id that is not an object of the scene or was removed earlier
    /// ([`SynthError::UnknownObject`], [`SynthError::RemovedObject`]), two different edits of one object
    /// ([`SynthError::ConflictingEdits`]), a change that is not finite ([`SynthError::NonFiniteMove`]).
    pub fn edited(&self, edits: &[ObjectEdit]) -> Result<SynthScene> {
        let by_object = self.checked_edits(edits)?;
        let mut scene = self.clone();
        for (id, edit) in by_object {
            let object = &mut scene.objects[id as usize];
            object.presence = object.presence.edited(&edit);
        }
        Ok(scene)
    }

    /// The edits that turn the generated scene into this one: one per edited object, in id order.
    pub fn edits(&self) -> Vec<ObjectEdit> {
        self.objects
            .iter()
            .filter_map(|object| match object.presence {
                Presence::Generated => None,
                Presence::Moved(change) => Some(ObjectEdit::Move { object: object.id, change }),
                Presence::Removed => Some(ObjectEdit::Remove(object.id)),
            })
            .collect()
    }

    /// The object `id` if the scene still draws it.
    pub fn drawn_object(&self, id: ObjectId) -> Result<&SceneObject> {
        let object = self.object(id).ok_or(SynthError::UnknownObject { object: id, objects: self.objects.len() })?;
        match object.presence {
            Presence::Removed => Err(SynthError::RemovedObject { object: id }),
            _ => Ok(object),
        }
    }

    /// The `dggt synth` command line that reproduces this scene (`DIR` stands for the output folder): the
    /// configuration's, then one flag per edited object, moves written about the object's generated box centre
    /// at the first frame's time (values rounded to 1e-9).
    pub fn command_line(&self) -> String {
        let mut line = self.config.command_line();
        for object in &self.objects {
            match object.presence {
                Presence::Generated => {}
                Presence::Removed => line += &format!(" --remove-object {}", object.id),
                Presence::Moved(change) => {
                    let change = change.about(object.generated_centre(SynthConfig::frame_time(0)));
                    let flag = MoveFlag { object: object.id, offset: change.offset, yaw_deg: change.yaw.to_degrees() };
                    line += &format!(" --move-object {flag}");
                }
            }
        }
        line
    }

    /// `edits` by object, checked against the scene.
    fn checked_edits(&self, edits: &[ObjectEdit]) -> Result<BTreeMap<ObjectId, ObjectEdit>> {
        let mut by_object = BTreeMap::new();
        for edit in edits {
            let object = edit.object();
            self.drawn_object(object)?;
            if let ObjectEdit::Move { change, .. } = edit {
                change.check(object)?;
            }
            match by_object.entry(object) {
                Entry::Vacant(entry) => {
                    entry.insert(*edit);
                }
                Entry::Occupied(entry) if entry.get() == edit => {}
                Entry::Occupied(_) => return Err(SynthError::ConflictingEdits { object }),
            }
        }
        Ok(by_object)
    }
}

/// A move as the `--move-object` flag of `dggt synth` spells it: `ID:DX,DY,DZ,YAW_DEG`, the offset in metres
/// (world axes: x along the road, y left, z up) and the yaw in degrees counter-clockwise seen from above, about
/// the object's box centre at the first frame's time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveFlag {
    pub object: ObjectId,
    /// Metres, world axes.
    pub offset: DVec3,
    /// Degrees, counter-clockwise seen from above.
    pub yaw_deg: f64,
}

/// The form of a [`MoveFlag`], for error messages.
const MOVE_FORM: &str = "expected ID:DX,DY,DZ,YAW_DEG: an object id, then the offset in metres and the yaw in \
                         degrees, all finite (e.g. 3:1.5,-2,0,90)";

impl MoveFlag {
    /// The edit this flag asks of `scene`: the move about the object's box centre at the first frame's time.
    pub fn edit(&self, scene: &SynthScene) -> Result<ObjectEdit> {
        let pivot = scene.drawn_object(self.object)?.centre(SynthConfig::frame_time(0));
        let change = WorldChange { offset: self.offset, yaw: self.yaw_deg.to_radians(), pivot };
        Ok(ObjectEdit::Move { object: self.object, change })
    }
}

impl FromStr for MoveFlag {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let (id, values) = text.split_once(':').ok_or_else(|| format!("no ':' after the object id; {MOVE_FORM}"))?;
        let object = id.trim().parse().map_err(|_| format!("{id:?} is not an object id; {MOVE_FORM}"))?;
        let numbers = values
            .split(',')
            .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(v))
            .collect::<std::result::Result<Vec<f64>, &str>>()
            .map_err(|v| format!("{v:?} is not a finite number; {MOVE_FORM}"))?;
        match numbers[..] {
            [dx, dy, dz, yaw_deg] => Ok(Self { object, offset: DVec3::new(dx, dy, dz), yaw_deg }),
            _ => Err(format!("{} values after ':', not 4; {MOVE_FORM}", numbers.len())),
        }
    }
}

/// `v` rounded to 1e-9, without a negative zero.
fn rounded(v: f64) -> f64 {
    (v * 1e9).round() / 1e9 + 0.0
}

impl fmt::Display for MoveFlag {
    /// `ID:DX,DY,DZ,YAW_DEG`, values rounded to 1e-9.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [dx, dy, dz] = self.offset.to_array().map(rounded);
        write!(f, "{}:{dx},{dy},{dz},{}", self.object, rounded(self.yaw_deg))
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

    #[test]
    fn move_flags_parse_print_and_name_the_expected_form() {
        let flag: MoveFlag = "12:1.5,-2,0,90".parse().unwrap();
        assert_eq!(flag, MoveFlag { object: 12, offset: DVec3::new(1.5, -2.0, 0.0), yaw_deg: 90.0 });
        assert_eq!(flag.to_string(), "12:1.5,-2,0,90");
        assert_eq!(MoveFlag { yaw_deg: 30f64.to_radians().to_degrees(), ..flag }.to_string(), "12:1.5,-2,0,30");
        for bad in ["12", "x:1,2,3,4", "-1:1,2,3,4", "3:1,2,3", "3:1,2,3,4,5", "3:1,nan,3,4", "3:1,,3,4"] {
            let message = bad.parse::<MoveFlag>().unwrap_err();
            assert!(message.contains("ID:DX,DY,DZ,YAW_DEG"), "{bad}: {message}");
        }
    }
}
