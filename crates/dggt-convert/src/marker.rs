//! The marker a finished scene gets, written last and atomically, and what a re-run makes of it.
//!
//! A batch run ([`crate::batch`]) records in the marker what the scene was converted from and with (its
//! [`Provenance`]). A later run skips the scene only when that record matches its own: the same segment, dataset
//! options, cameras, sky masks and converter version. Anything else at the scene's place (a marker recording
//! another conversion, one recording none, a folder without a marker) is a [`Refusal`], so a re-run never
//! passes off an old scene as the one asked for, nor writes over a folder it did not finish.

use std::fmt;
use std::path::{Path, PathBuf};

use dggt_data::io;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::instances::json_bytes;

/// File name of the marker inside a scene folder.
pub const DONE_MARKER: &str = "convert_done.json";

/// What the marker records about the conversion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DoneMarker {
    pub converter: String,
    pub source: PathBuf,
    pub frames: usize,
    pub cameras: Vec<usize>,
    pub instances: usize,
    pub lidar_frames: usize,
    /// What the scene was converted from and with; absent in markers of older versions and of scenes converted
    /// outside a batch run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<Provenance>,
}

/// What a scene is converted from and with: everything that makes two conversions' scenes differ.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Provenance {
    /// The segment's file or folder (nuScenes: the data root), as an absolute path.
    pub source: PathBuf,
    /// The segment's name (the file or folder name; nuScenes: the scene's name).
    pub segment: String,
    /// The dataset and its options (nuScenes: the release and the frame rate).
    pub dataset: String,
    /// Export camera ids.
    pub cameras: Vec<usize>,
    /// `none` or `lidar`.
    pub sky_masks: String,
    /// `none` or `boxes` ([`DepthFlows`](crate::depth_flows::DepthFlows)); `none` in markers of older versions.
    #[serde(default = "no_depth_flows")]
    pub depth_flows: String,
    /// `dggt-convert` and its version.
    pub converter: String,
}

impl Provenance {
    /// Every field as (name, value), in the order a difference is reported.
    fn fields(&self) -> [(&'static str, String); 7] {
        [
            ("source", self.source.display().to_string()),
            ("segment", self.segment.clone()),
            ("dataset", self.dataset.clone()),
            ("cameras", format!("{:?}", self.cameras)),
            ("sky masks", self.sky_masks.clone()),
            ("depth flows", self.depth_flows.clone()),
            ("converter version", self.converter.clone()),
        ]
    }
}

fn no_depth_flows() -> String {
    crate::depth_flows::DepthFlows::None.name().into()
}

/// Why an existing scene folder is neither skipped nor converted over.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Refusal {
    /// The marker records another conversion; `field` is the first that differs.
    Differs { field: &'static str, recorded: String, requested: String },
    /// The marker does not record what the scene was converted from (an older version wrote it).
    Unrecorded,
    /// The folder has no done marker: no finished conversion wrote it.
    Unmarked,
    /// The marker cannot be read.
    Unreadable(String),
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Differs { field, recorded, requested } => {
                write!(f, "converted earlier with {field} {recorded} (this run: {requested})")
            }
            Self::Unrecorded => {
                write!(f, "its {DONE_MARKER} does not record the source and options it was converted with")
            }
            Self::Unmarked => write!(f, "the folder exists but has no {DONE_MARKER}: no finished conversion wrote it"),
            Self::Unreadable(detail) => write!(f, "its {DONE_MARKER} cannot be read: {detail}"),
        }
    }
}

/// What a run finds at a scene's folder.
#[derive(Debug, Clone, PartialEq)]
pub enum Found {
    /// Nothing: the scene is to be converted.
    Nothing,
    /// A scene finished from the same source with the same options.
    Done(DoneMarker),
    /// Something the run must not skip nor replace unasked.
    Refused(Refusal),
}

/// What the folder `scene` holds, compared with the conversion `wanted`.
pub fn examine(scene: &Path, wanted: &Provenance) -> Found {
    if !scene.exists() {
        return Found::Nothing;
    }
    let path = scene.join(DONE_MARKER);
    let bytes = match std::fs::read(&path) {
        Ok(bytes) => bytes,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Found::Refused(Refusal::Unmarked),
        Err(error) => return Found::Refused(Refusal::Unreadable(error.to_string())),
    };
    let marker: DoneMarker = match serde_json::from_slice(&bytes) {
        Ok(marker) => marker,
        Err(error) => return Found::Refused(Refusal::Unreadable(error.to_string())),
    };
    let Some(recorded) = &marker.provenance else { return Found::Refused(Refusal::Unrecorded) };
    let difference = recorded.fields().into_iter().zip(wanted.fields()).find(|(old, new)| old.1 != new.1);
    match difference {
        Some(((field, recorded), (_, requested))) => Found::Refused(Refusal::Differs { field, recorded, requested }),
        None => Found::Done(marker),
    }
}

/// The marker of a finished scene, or `None` when the scene is missing or unfinished.
pub fn read_done(scene: &Path) -> Option<DoneMarker> {
    let bytes = std::fs::read(scene.join(DONE_MARKER)).ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// Marks `scene` finished.
pub fn write_done(scene: &Path, marker: &DoneMarker) -> Result<()> {
    Ok(io::write_atomically(&scene.join(DONE_MARKER), &json_bytes(DONE_MARKER, marker)?)?)
}
