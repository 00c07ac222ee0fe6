//! Which checkpoint folder to use. A run writes `checkpoints/step-NNNNNNNN/` folders and a `checkpoints/latest`
//! pointer naming the newest complete one (a folder is complete once it holds its run state); a folder is used
//! only when its files match their checksums ([`crate::checksums`]) for its reader. A checkpoint named directly
//! must be intact; of a run, a damaged or incomplete newest checkpoint gives way, with a warning naming what is
//! wrong, to the newest other one that is complete and intact.

use std::fs;
use std::path::{Path, PathBuf};

use crate::checksums::{self, Purpose, Verified};
use crate::error::CheckpointError;
use crate::files::{LATEST, MODEL_CONFIG_FILE, STATE_FILE};

/// The checkpoint to use under `root` (`run/checkpoints`), if any: the one `latest` names when it is complete
/// and its files match their checksums ([`checksums`]) for `purpose`; otherwise, with a warning naming what is
/// wrong (a run killed while rewriting it, a damaged file), the newest other complete checkpoint that matches.
/// An error when none does.
pub fn latest(root: &Path, purpose: Purpose) -> Result<Option<PathBuf>, CheckpointError> {
    let pointer = root.join(LATEST);
    if !pointer.exists() {
        return Ok(None);
    }
    let name = fs::read_to_string(&pointer).map_err(|e| CheckpointError::file(&pointer, e))?;
    let named = root.join(name.trim());
    let others = complete_folders(root)?.into_iter().rev().filter(|dir| dir != &named);
    let mut passed_over: Vec<String> = Vec::new();
    for dir in std::iter::once(named.clone()).chain(others) {
        match usable(&dir, purpose) {
            Ok(()) => {
                if !passed_over.is_empty() {
                    tracing::warn!(using = %dir.display(), "passed over: {}", passed_over.join("; "));
                }
                return Ok(Some(dir));
            }
            Err(reason) => passed_over.push(reason.to_string()),
        }
    }
    Err(CheckpointError::file(root, format!("no usable checkpoint: {}", passed_over.join("; "))))
}

/// Why a checkpoint folder cannot be used.
#[derive(Debug, thiserror::Error)]
enum Unusable {
    /// A folder without its run state (a run killed while writing it).
    #[error("{} is incomplete (no {STATE_FILE})", .0.display())]
    Incomplete(PathBuf),
    /// Files that do not match their checksums.
    #[error(transparent)]
    Damaged(CheckpointError),
}

/// Whether the checkpoint folder `dir` can be used for `purpose`: an error when incomplete or damaged.
fn usable(dir: &Path, purpose: Purpose) -> Result<(), Unusable> {
    if !dir.join(STATE_FILE).is_file() {
        return Err(Unusable::Incomplete(dir.to_path_buf()));
    }
    verified(dir, purpose).map_err(Unusable::Damaged)
}

/// Checks the files of the checkpoint folder `dir` that `purpose` reads against their checksums: an error
/// naming the damaged file, a warning when the folder records none (an older version's).
pub fn verified(dir: &Path, purpose: Purpose) -> Result<(), CheckpointError> {
    match checksums::verify(dir, purpose) {
        Ok(Verified::Intact) => Ok(()),
        Ok(Verified::Unrecorded) => {
            tracing::warn!(
                checkpoint = %dir.display(),
                "the checkpoint records no checksums (written by an older version): its files are not verified"
            );
            Ok(())
        }
        Err(damage) => Err(CheckpointError::Damaged { dir: dir.to_path_buf(), damage }),
    }
}

/// The complete `step-*` folders under `root` (those holding a run state), oldest first.
fn complete_folders(root: &Path) -> Result<Vec<PathBuf>, CheckpointError> {
    let entries = fs::read_dir(root).map_err(|e| CheckpointError::file(root, e))?;
    let mut complete: Vec<PathBuf> = entries
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("step-")))
        .filter(|p| p.join(STATE_FILE).is_file())
        .collect();
    complete.sort();
    Ok(complete)
}

/// The checkpoint folder of a `step-N` folder, a run's `checkpoints/` folder or a run folder, its network's
/// files verified: a `step-N` folder named directly must be intact; of a run, the newest intact checkpoint
/// is used ([`latest`]).
pub fn checkpoint_dir(path: &Path) -> Result<PathBuf, CheckpointError> {
    if path.join(MODEL_CONFIG_FILE).is_file() {
        verified(path, Purpose::Inference)?;
        return Ok(path.to_path_buf());
    }
    for root in [path.to_path_buf(), path.join("checkpoints")] {
        if root.join(LATEST).is_file()
            && let Some(dir) = latest(&root, Purpose::Inference)?
        {
            return Ok(dir);
        }
    }
    Err(CheckpointError::file(
        path,
        "a folder without model.json or a `latest` checkpoint pointer (expected a trainer checkpoint folder, a run \
         folder, or a .pt/.safetensors file)",
    ))
}
