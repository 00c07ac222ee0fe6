//! The marker a finished scene gets, written last and atomically, and what a re-run makes of it.
//!
//! A batch run ([`crate::batch`]) records in the marker what the scene was converted from and with (its
//! [`Provenance`]). A later run skips the scene only when that record matches its own: the same segment, unchanged
//! since ([`source_stamp`]: the sizes and modification times of its files), dataset options, cameras, sky masks
//! and converter version. Anything else at the scene's place (a marker recording
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
    /// [`source_stamp`] of the segment's file or folder (nuScenes: the version's tables); `unrecorded` in markers
    /// of older versions, which therefore differ from any run's.
    #[serde(default = "unrecorded_stamp")]
    pub source_stamp: String,
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
    /// [`DynamicMaskStyle::describe`](crate::masks::DynamicMaskStyle::describe); `drivestudio` in markers of
    /// older versions.
    #[serde(default = "drivestudio_masks")]
    pub dynamic_masks: String,
    /// `dggt-convert` and its version.
    pub converter: String,
}

impl Provenance {
    /// Every field as (name, value), in the order a difference is reported.
    fn fields(&self) -> [(&'static str, String); 9] {
        [
            ("source", self.source.display().to_string()),
            ("source files", self.source_stamp.clone()),
            ("segment", self.segment.clone()),
            ("dataset", self.dataset.clone()),
            ("cameras", format!("{:?}", self.cameras)),
            ("sky masks", self.sky_masks.clone()),
            ("depth flows", self.depth_flows.clone()),
            ("dynamic masks", self.dynamic_masks.clone()),
            ("converter version", self.converter.clone()),
        ]
    }
}

fn unrecorded_stamp() -> String {
    "unrecorded".into()
}

/// The sizes and modification times of a conversion's source, so that a source replaced behind the same path
/// reads as another conversion: a file's size and time; for a folder, its files' count, total size and newest
/// time, with a digest of every file's relative path, size and time (a file replaced by an older one changes it
/// too). Metadata only: no file is read. A source that cannot be listed says so (its conversion then fails
/// naming why).
pub fn source_stamp(path: &Path) -> String {
    let mut files = Vec::new();
    if let Err(error) = stamp_files(path, Path::new(""), &mut files) {
        return format!("unreadable ({error})");
    }
    let bytes: u64 = files.iter().map(|file| file.bytes).sum();
    let newest = files.iter().map(|file| file.modified_ns).max().unwrap_or(0);
    let (seconds, nanos) = (newest / 1_000_000_000, newest % 1_000_000_000);
    if files.len() == 1 && files[0].relative.as_os_str().is_empty() {
        return format!("{bytes} bytes, modified at {seconds}.{nanos:09} s");
    }
    let digest = files.iter().fold(dggt_data::random::splitmix64(files.len() as u64), |digest, file| {
        let text = format!("{}\0{}\0{}", file.relative.display(), file.bytes, file.modified_ns);
        text.bytes().fold(digest, |digest, byte| dggt_data::random::splitmix64(digest ^ u64::from(byte)))
    });
    format!("{} files, {bytes} bytes, newest modified at {seconds}.{nanos:09} s, digest {digest:016x}", files.len())
}

/// A file under a stamped source: its path relative to the source, size, and modification time (ns since the
/// Unix epoch).
struct StampedFile {
    relative: PathBuf,
    bytes: u64,
    modified_ns: u128,
}

/// Adds `path` (at `relative` under the source) or every file under it, in name order, to `files`.
fn stamp_files(path: &Path, relative: &Path, files: &mut Vec<StampedFile>) -> std::io::Result<()> {
    let metadata = std::fs::metadata(path)?;
    if metadata.is_dir() {
        let mut names: Vec<_> =
            std::fs::read_dir(path)?.map(|entry| entry.map(|e| e.file_name())).collect::<Result<_, _>>()?;
        names.sort();
        for name in names {
            stamp_files(&path.join(&name), &relative.join(&name), files)?;
        }
        return Ok(());
    }
    let modified = metadata.modified()?.duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    files.push(StampedFile {
        relative: relative.to_path_buf(),
        bytes: metadata.len(),
        modified_ns: modified.as_nanos(),
    });
    Ok(())
}

fn drivestudio_masks() -> String {
    crate::masks::DynamicMaskStyle::Drivestudio.describe()
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
    /// A scene finished from the same source with the same options (boxed: the marker is large).
    Done(Box<DoneMarker>),
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
        None => Found::Done(Box::new(marker)),
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

#[cfg(test)]
mod tests {
    use std::time::{Duration, SystemTime};

    use super::*;

    fn set_time(path: &Path, seconds: u64) {
        let file = std::fs::File::options().append(true).open(path).unwrap();
        file.set_modified(SystemTime::UNIX_EPOCH + Duration::from_secs(seconds)).unwrap();
    }

    #[test]
    fn a_files_stamp_is_its_size_and_time_and_changes_with_either() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("segment.tfrecord");
        std::fs::write(&file, b"first").unwrap();
        set_time(&file, 1_700_000_000);
        let stamp = source_stamp(&file);
        assert_eq!(stamp, "5 bytes, modified at 1700000000.000000000 s");
        assert_eq!(source_stamp(&file), stamp, "reading it again changes nothing");
        std::fs::write(&file, b"other").unwrap();
        set_time(&file, 1_700_000_000);
        assert_eq!(source_stamp(&file), stamp, "same size and time: metadata cannot tell (documented)");
        set_time(&file, 1_700_000_001);
        assert_ne!(source_stamp(&file), stamp, "a replaced file's time");
        std::fs::write(&file, b"longer one").unwrap();
        set_time(&file, 1_700_000_000);
        assert_ne!(source_stamp(&file), stamp, "a replaced file's size");
        assert!(source_stamp(&dir.path().join("gone")).starts_with("unreadable"));
    }

    #[test]
    fn a_folders_stamp_changes_when_any_file_under_it_does_even_to_an_older_time() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("log");
        std::fs::create_dir_all(log.join("sensors")).unwrap();
        for (name, seconds) in [("calibration.feather", 10), ("sensors/a.jpg", 20), ("sensors/b.jpg", 30)] {
            std::fs::write(log.join(name), name).unwrap();
            set_time(&log.join(name), seconds);
        }
        let stamp = source_stamp(&log);
        assert!(stamp.starts_with("3 files, 45 bytes, newest modified at 30.000000000 s, digest "), "{stamp}");
        assert_eq!(source_stamp(&log), stamp);
        set_time(&log.join("sensors/a.jpg"), 15);
        assert_ne!(source_stamp(&log), stamp, "an older time on one file");
        set_time(&log.join("sensors/a.jpg"), 20);
        assert_eq!(source_stamp(&log), stamp);
        std::fs::rename(log.join("sensors/b.jpg"), log.join("sensors/c.jpg")).unwrap();
        assert_ne!(source_stamp(&log), stamp, "a renamed file");
    }

    #[test]
    fn a_marker_of_an_older_version_without_a_stamp_is_another_conversion() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("000");
        std::fs::create_dir_all(&scene).unwrap();
        let older = r#"{"converter":"dggt-convert","source":"/data/seg.tfrecord","frames":2,"cameras":[0],"instances":0,
            "lidar_frames":2,"provenance":{"source":"/data/seg.tfrecord","segment":"seg.tfrecord","dataset":"waymo",
            "cameras":[0],"sky_masks":"none","converter":"dggt-convert 0.1.0"}}"#;
        std::fs::write(scene.join(DONE_MARKER), older).unwrap();
        let recorded = read_done(&scene).unwrap().provenance.unwrap();
        assert_eq!(recorded.source_stamp, "unrecorded");
        let wanted = Provenance { source_stamp: "5 bytes, modified at 1.000000000 s".into(), ..recorded };
        let found = examine(&scene, &wanted);
        let Found::Refused(Refusal::Differs { field, recorded, .. }) = &found else { panic!("{found:?}") };
        assert_eq!((*field, recorded.as_str()), ("source files", "unrecorded"));
    }
}
