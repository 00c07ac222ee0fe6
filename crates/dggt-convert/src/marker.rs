//! The marker a finished scene gets, written last and atomically: a scene folder with it is complete and a
//! re-run skips it; a scene folder without it is rewritten from the start.

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
