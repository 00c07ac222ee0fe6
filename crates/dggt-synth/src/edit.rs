//! Edited copies of a scene: objects removed, or moved by a rigid change, as ground truth for scene editing.
//!
//! Scene editing (removing or moving an object of a reconstruction) is checked against renders of the same scene
//! without the object, or with the object where the edit puts it. [`SynthScene::edited`] gives that scene: a
//! removed object is placed nowhere, so no camera ray, lidar beam, mask or instance list meets it; a moved object
//! is drawn at its moved pose at every time, and its velocity (the scene flow) is the moved object's. Shading
//! has no shadows, so no other surface changes. What an edit does to one object, and its conventions, are
//! [`crate::change`]'s; the `--move-object` flag that asks for a move is a [`MoveFlag`].
//!
//! Object ids never change: an edited object keeps its index in [`SynthScene::objects`], and a removed one stays
//! listed there with [`Presence::Removed`].

use std::collections::BTreeMap;
use std::collections::btree_map::Entry;
use std::fmt;
use std::str::FromStr;

use dggt_geom::glam::DVec3;

use crate::change::{ObjectEdit, Presence, WorldChange};
use crate::config::SynthConfig;
use crate::error::{Result, SynthError};
use crate::object_id::ObjectId;
use crate::scene::{SceneObject, SynthScene};

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
    use super::*;

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
