//! The edits as written on the command line, parsed into values with their units stated. Each keeps the text
//! it came from, so that every later error names the argument at fault.

use std::path::PathBuf;

use dggt_geom::glam::DVec3;

use crate::error::EditError;

/// One edit and the argument it was written as (`--move 2:0,0,3.5,0`).
#[derive(Debug, Clone, PartialEq)]
pub struct Edit {
    pub argument: String,
    pub kind: EditKind,
}

/// What one edit does to an instance (ids as `summary.json` lists them).
#[derive(Debug, Clone, PartialEq)]
pub enum EditKind {
    /// The instance is not drawn at any time.
    Remove { instance: u32 },
    /// At every time the instance is turned by `yaw_degrees` about the world's up axis through its centre then,
    /// and shifted by `offset` (world axes and units).
    Move { instance: u32, offset: DVec3, yaw_degrees: f64 },
    /// An object of another reconstruction drawn in this one.
    Insert(Insertion),
    /// Every Gaussian whose mean lies in the world-axis-aligned box `[min, max]` is not drawn (world units).
    RemoveBox { min: DVec3, max: DVec3 },
}

/// Instance `instance` of the reconstruction saved at `source` drawn in this one: its centre at its first
/// appearance placed at `position` (this world), turned by `yaw_degrees` about this world's up axis (after its
/// own world's up is turned onto this one's); it keeps its own Gaussians and motion, at the same scene times.
#[derive(Debug, Clone, PartialEq)]
pub struct Insertion {
    pub source: PathBuf,
    pub instance: u32,
    pub position: DVec3,
    pub yaw_degrees: f64,
}

impl Edit {
    /// `--remove ID`.
    pub fn remove(text: &str) -> Result<Self, EditError> {
        let argument = format!("--remove {text}");
        let instance = parse_id(&argument, text)?;
        Ok(Self { argument, kind: EditKind::Remove { instance } })
    }

    /// `--move ID:DX,DY,DZ,YAW` (world units, degrees).
    pub fn moved(text: &str) -> Result<Self, EditError> {
        let argument = format!("--move {text}");
        let (id, pose) = text
            .split_once(':')
            .ok_or_else(|| EditError::argument(&argument, "expected ID:DX,DY,DZ,YAW (world units and degrees)"))?;
        let instance = parse_id(&argument, id)?;
        let [dx, dy, dz, yaw_degrees] = parse_numbers(&argument, pose, "DX,DY,DZ,YAW")?;
        Ok(Self { argument, kind: EditKind::Move { instance, offset: DVec3::new(dx, dy, dz), yaw_degrees } })
    }

    /// `--insert SCENE:ID@X,Y,Z,YAW`: `SCENE` a reconstruction folder or its `scene.safetensors` (it may itself
    /// hold `:`; the last one before `@` separates the id).
    pub fn insert(text: &str) -> Result<Self, EditError> {
        let argument = format!("--insert {text}");
        let expected = "expected SCENE:ID@X,Y,Z,YAW (a reconstruction, an instance id, a position and degrees)";
        let (object, pose) = text.rsplit_once('@').ok_or_else(|| EditError::argument(&argument, expected))?;
        let (source, id) = object.rsplit_once(':').ok_or_else(|| EditError::argument(&argument, expected))?;
        if source.is_empty() {
            return Err(EditError::argument(&argument, expected));
        }
        let instance = parse_id(&argument, id)?;
        let [x, y, z, yaw_degrees] = parse_numbers(&argument, pose, "X,Y,Z,YAW")?;
        let kind =
            EditKind::Insert(Insertion { source: source.into(), instance, position: DVec3::new(x, y, z), yaw_degrees });
        Ok(Self { argument, kind })
    }

    /// `--remove-box X0,Y0,Z0,X1,Y1,Z1` (two opposite corners, world units).
    pub fn remove_box(text: &str) -> Result<Self, EditError> {
        let argument = format!("--remove-box {text}");
        let [x0, y0, z0, x1, y1, z1] = parse_numbers(&argument, text, "X0,Y0,Z0,X1,Y1,Z1")?;
        let (a, b) = (DVec3::new(x0, y0, z0), DVec3::new(x1, y1, z1));
        Ok(Self { argument, kind: EditKind::RemoveBox { min: a.min(b), max: a.max(b) } })
    }

    /// The instance of the edited scene this edit changes; `None` for an insertion or a box.
    pub fn target_instance(&self) -> Option<u32> {
        match self.kind {
            EditKind::Remove { instance } | EditKind::Move { instance, .. } => Some(instance),
            EditKind::Insert(_) | EditKind::RemoveBox { .. } => None,
        }
    }
}

fn parse_id(argument: &str, text: &str) -> Result<u32, EditError> {
    text.trim()
        .parse()
        .map_err(|_| EditError::argument(argument, format!("`{text}` is not an instance id (a whole number)")))
}

/// `N` comma-separated finite numbers, named by `names` in errors.
fn parse_numbers<const N: usize>(argument: &str, text: &str, names: &str) -> Result<[f64; N], EditError> {
    let values: Vec<&str> = text.split(',').collect();
    if values.len() != N {
        return Err(EditError::argument(argument, format!("expected {N} numbers {names}, found `{text}`")));
    }
    let mut numbers = [0.0; N];
    for (number, value) in numbers.iter_mut().zip(values) {
        *number = value
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| EditError::argument(argument, format!("`{value}` in {names} is not a finite number")))?;
    }
    Ok(numbers)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edits_parse_with_their_units() {
        let moved = Edit::moved("3:1.5,0,-2,90").unwrap();
        assert_eq!(moved.kind, EditKind::Move { instance: 3, offset: DVec3::new(1.5, 0.0, -2.0), yaw_degrees: 90.0 });
        assert_eq!(moved.argument, "--move 3:1.5,0,-2,90");
        let inserted = Edit::insert("C:/runs/a:b/scene.safetensors:4@1,2,3,-45").unwrap();
        let expected = EditKind::Insert(Insertion {
            source: "C:/runs/a:b/scene.safetensors".into(),
            instance: 4,
            position: DVec3::new(1.0, 2.0, 3.0),
            yaw_degrees: -45.0,
        });
        assert_eq!(inserted.kind, expected);
        assert_eq!(Edit::remove("7").unwrap().target_instance(), Some(7));
        let corners = Edit::remove_box("4,1,0,2,-1,3").unwrap();
        assert_eq!(
            corners.kind,
            EditKind::RemoveBox { min: DVec3::new(2.0, -1.0, 0.0), max: DVec3::new(4.0, 1.0, 3.0) }
        );
    }

    #[test]
    fn malformed_edits_name_the_argument() {
        for (result, argument) in [
            (Edit::remove("car"), "--remove car"),
            (Edit::moved("1:0,0,NaN,0"), "--move 1:0,0,NaN,0"),
            (Edit::moved("1:0,0,0"), "--move 1:0,0,0"),
            (Edit::moved("1"), "--move 1"),
            (Edit::insert("scene:2@0,0,0,inf"), "--insert scene:2@0,0,0,inf"),
            (Edit::insert("2@0,0,0,0"), "--insert 2@0,0,0,0"),
            (Edit::remove_box("0,0,0,1,1"), "--remove-box 0,0,0,1,1"),
        ] {
            let message = result.unwrap_err().to_string();
            assert!(message.starts_with(argument), "{message}");
        }
    }
}
