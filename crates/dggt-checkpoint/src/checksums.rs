//! Checksums of a training checkpoint's files: recorded when the checkpoint is written, checked before it is
//! used.
//!
//! A checkpoint folder lists the size and CRC-32C of each of its files in `checksums.json`, written after them
//! and before `state.json`, the file that marks the folder complete (its checksum is taken from the bytes about
//! to be written), so every complete folder of this version has its manifest. Flipped bits on a disk or in a
//! copy, a truncated or missing file, a file edited by hand: each is caught before a weight is used. CRC-32C
//! (hardware-accelerated on x86-64 and ARM) finds every burst of up to 32 flipped bits and all but about one
//! in four billion other changes; it guards against accidents, not against someone rewriting the manifest too.
//!
//! What is checked depends on the reader ([`Purpose`]): inference reads the network's files only (a checkpoint
//! stripped of its optimiser state to share the network still loads, and a large one is not read twice); a
//! resume reads everything. Checkpoints written before the manifest existed have none and are used
//! unverified ([`Verified::Unrecorded`]), with a warning from the caller.

use std::collections::BTreeMap;
use std::fs;
use std::io::Read;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{CheckpointError, Damage};
use crate::files::{MANIFEST_FILE, MODEL_CONFIG_FILE, MODEL_FILE, PREPROCESS_FILE, STATE_FILE};

/// The checksum the manifest records.
const ALGORITHM: &str = "crc32c";
/// The files inference reads from a checkpoint folder.
const INFERENCE_FILES: [&str; 4] = [MODEL_FILE, MODEL_CONFIG_FILE, PREPROCESS_FILE, STATE_FILE];

/// Who reads a checkpoint, and so which of its files must be intact.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Purpose {
    /// The network: weights, configuration, preprocessing and run state.
    Inference,
    /// Continuing the run: every file the checkpoint holds.
    Resume,
}

/// How a checkpoint folder stands against its manifest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verified {
    /// Every file the reader needs matches its recorded size and checksum.
    Intact,
    /// The folder has no manifest (written before checksums were recorded): nothing could be checked.
    Unrecorded,
}

/// The size and checksum of one file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
struct FileSum {
    bytes: u64,
    crc32c: u32,
}

#[derive(Debug, Serialize, Deserialize)]
struct Manifest {
    algorithm: String,
    /// By file name within the folder.
    files: BTreeMap<String, FileSum>,
}

/// Writes the manifest of `dir`: the files `written` there and the `pending` ones (name, bytes), which the
/// caller writes next.
pub fn write_manifest(dir: &Path, written: &[&str], pending: &[(&str, &[u8])]) -> Result<(), CheckpointError> {
    let mut files = BTreeMap::new();
    for name in written {
        let path = dir.join(name);
        let sum = file_sum(&path).map_err(|e| CheckpointError::file(&path, e))?;
        files.insert(name.to_string(), sum);
    }
    for (name, bytes) in pending {
        files.insert(name.to_string(), FileSum { bytes: bytes.len() as u64, crc32c: crc32c::crc32c(bytes) });
    }
    let manifest = Manifest { algorithm: ALGORITHM.into(), files };
    let text = serde_json::to_string_pretty(&manifest).expect("manifests serialise");
    let path = dir.join(MANIFEST_FILE);
    dggt_data::io::write_atomically(&path, text.as_bytes()).map_err(|e| CheckpointError::file(&path, e))
}

/// Checks the files of `dir` that `purpose` reads against its manifest.
pub fn verify(dir: &Path, purpose: Purpose) -> Result<Verified, Damage> {
    let Some(manifest) = read_manifest(dir)? else { return Ok(Verified::Unrecorded) };
    let needed = manifest.files.iter().filter(|(name, _)| match purpose {
        Purpose::Inference => INFERENCE_FILES.contains(&name.as_str()),
        Purpose::Resume => true,
    });
    for (name, recorded) in needed {
        let path = dir.join(name);
        if !path.is_file() {
            return Err(Damage::Missing { file: name.clone() });
        }
        let found = file_sum(&path).map_err(|e| Damage::Unreadable { file: name.clone(), detail: e.to_string() })?;
        if found.bytes != recorded.bytes {
            return Err(Damage::Size { file: name.clone(), recorded: recorded.bytes, found: found.bytes });
        }
        if found.crc32c != recorded.crc32c {
            return Err(Damage::Checksum { file: name.clone(), recorded: recorded.crc32c, found: found.crc32c });
        }
    }
    Ok(Verified::Intact)
}

/// The manifest of `dir`; `None` when it has none.
fn read_manifest(dir: &Path) -> Result<Option<Manifest>, Damage> {
    let path = dir.join(MANIFEST_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let unreadable = |detail: String| Damage::Manifest { detail };
    let bytes = fs::read(&path).map_err(|e| unreadable(e.to_string()))?;
    let manifest: Manifest = serde_json::from_slice(&bytes).map_err(|e| unreadable(e.to_string()))?;
    if manifest.algorithm != ALGORITHM {
        return Err(unreadable(format!("unknown algorithm `{}` (expected `{ALGORITHM}`)", manifest.algorithm)));
    }
    Ok(Some(manifest))
}

/// The size and CRC-32C of the file at `path`, read in pieces (a checkpoint's files can be many gigabytes).
fn file_sum(path: &Path) -> std::io::Result<FileSum> {
    let mut file = fs::File::open(path)?;
    let mut buffer = vec![0u8; 1 << 20];
    let (mut bytes, mut crc) = (0u64, 0u32);
    loop {
        let read = file.read(&mut buffer)?;
        if read == 0 {
            return Ok(FileSum { bytes, crc32c: crc });
        }
        crc = crc32c::crc32c_append(crc, &buffer[..read]);
        bytes += read as u64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streamed_sums_equal_the_one_shot_checksum() {
        let dir = tempfile::tempdir().unwrap();
        let bytes: Vec<u8> = (0..3_000_000u32).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(dir.path().join("a"), &bytes).unwrap();
        let sum = file_sum(&dir.path().join("a")).unwrap();
        assert_eq!(sum, FileSum { bytes: bytes.len() as u64, crc32c: crc32c::crc32c(&bytes) });
    }
}
