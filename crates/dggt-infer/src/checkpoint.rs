//! Reading the network of this project's training checkpoints.
//!
//! A run writes `checkpoints/step-NNNNNNNN/` folders and a `checkpoints/latest` pointer naming the newest
//! complete one. Each folder holds the network (`model.bpk`, burnpack), its configuration (`model.json`) and
//! the input preprocessing it was trained with (`preprocess.json`; older checkpoints lack it); the optimiser
//! and run state beside them are the trainer's, and `checksums.json` the checksums of them all
//! ([`checksums`]). This module finds the checkpoint to use (complete, its files intact) and reads what
//! inference needs: the configuration, the preprocessing and the weights.

use std::fs;
use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::Bytes;
use dggt_data::Preprocess;
use dggt_model::ModelConfig;

use crate::checksums::{self, Purpose, Verified};
use crate::error::InferError;

/// The pointer file naming the newest complete checkpoint folder.
pub const LATEST: &str = "latest";
/// The network's weights in a checkpoint folder.
pub const MODEL_FILE: &str = "model.bpk";
/// The network's configuration in a checkpoint folder.
pub const MODEL_CONFIG_FILE: &str = "model.json";
/// The input preprocessing of training in a checkpoint folder.
pub const PREPROCESS_FILE: &str = "preprocess.json";
/// The run state in a checkpoint folder; its presence marks the folder complete.
pub const STATE_FILE: &str = "state.json";

fn read(path: &Path) -> Result<Vec<u8>, InferError> {
    fs::read(path).map_err(|e| InferError::checkpoint(path, e))
}

/// The checkpoint to use under `root` (`run/checkpoints`), if any: the one `latest` names when it is complete
/// and its files match their checksums ([`checksums`]) for `purpose`; otherwise, with a warning naming what is
/// wrong (a run killed while rewriting it, a damaged file), the newest other complete checkpoint that matches.
/// An error when none does.
pub fn latest(root: &Path, purpose: Purpose) -> Result<Option<PathBuf>, InferError> {
    let pointer = root.join(LATEST);
    if !pointer.exists() {
        return Ok(None);
    }
    let name = fs::read_to_string(&pointer).map_err(|e| InferError::checkpoint(&pointer, e))?;
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
    Err(InferError::checkpoint(root, format!("no usable checkpoint: {}", passed_over.join("; "))))
}

/// Why a checkpoint folder cannot be used.
#[derive(Debug, thiserror::Error)]
enum Unusable {
    /// A folder without its run state (a run killed while writing it).
    #[error("{} is incomplete (no {STATE_FILE})", .0.display())]
    Incomplete(PathBuf),
    /// Files that do not match their checksums.
    #[error(transparent)]
    Damaged(InferError),
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
pub fn verified(dir: &Path, purpose: Purpose) -> Result<(), InferError> {
    match checksums::verify(dir, purpose) {
        Ok(Verified::Intact) => Ok(()),
        Ok(Verified::Unrecorded) => {
            tracing::warn!(
                checkpoint = %dir.display(),
                "the checkpoint records no checksums (written by an older version): its files are not verified"
            );
            Ok(())
        }
        Err(damage) => Err(InferError::DamagedCheckpoint { dir: dir.to_path_buf(), damage }),
    }
}

/// The complete `step-*` folders under `root` (those holding a run state), oldest first.
fn complete_folders(root: &Path) -> Result<Vec<PathBuf>, InferError> {
    let entries = fs::read_dir(root).map_err(|e| InferError::checkpoint(root, e))?;
    let mut complete: Vec<PathBuf> = entries
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("step-")))
        .filter(|p| p.join(STATE_FILE).is_file())
        .collect();
    complete.sort();
    Ok(complete)
}

/// The network configuration stored in a checkpoint folder.
pub fn read_model_config(dir: &Path) -> Result<ModelConfig, InferError> {
    let path = dir.join(MODEL_CONFIG_FILE);
    serde_json::from_slice(&read(&path)?).map_err(|e| InferError::checkpoint(&path, e))
}

/// The input preprocessing a checkpoint folder records; `None` for a checkpoint written before it was recorded.
pub fn read_preprocess(dir: &Path) -> Result<Option<Preprocess>, InferError> {
    let path = dir.join(PREPROCESS_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let preprocess: Preprocess = serde_json::from_slice(&read(&path)?).map_err(|e| InferError::checkpoint(&path, e))?;
    preprocess.validate().map_err(|e| InferError::checkpoint(&path, e))?;
    Ok(Some(preprocess))
}

/// Loads the network of a checkpoint folder into `model` (built from the stored configuration); any module
/// saved the same way loads alike.
pub fn load_model<M: Module>(dir: &Path, model: M) -> Result<M, InferError> {
    load_module_file(&dir.join(MODEL_FILE), model)
}

/// Loads the module file `path` (burnpack, as a checkpoint writes its modules) into `model`.
pub fn load_module_file<M: Module>(path: &Path, model: M) -> Result<M, InferError> {
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(read(path)?))
        .map_err(|e| InferError::checkpoint(path, format!("{e:?}")))?;
    model.try_load_record(record).map_err(|e| InferError::checkpoint(path, format!("does not fit the network: {e:?}")))
}

/// The checkpoint folder of a `step-N` folder, a run's `checkpoints/` folder or a run folder, its network's
/// files verified: a `step-N` folder named directly must be intact; of a run, the newest intact checkpoint
/// is used ([`latest`]).
pub fn checkpoint_dir(path: &Path) -> Result<PathBuf, InferError> {
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
    Err(InferError::checkpoint(
        path,
        "a folder without model.json or a `latest` checkpoint pointer (expected a trainer checkpoint folder, a run \
         folder, or a .pt/.safetensors file)",
    ))
}
