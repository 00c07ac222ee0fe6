//! Reading the network of this project's training checkpoints.
//!
//! A run writes `checkpoints/step-NNNNNNNN/` folders and a `checkpoints/latest` pointer naming the newest
//! complete one. Each folder holds the network (`model.bpk`, burnpack), its configuration (`model.json`) and
//! the input preprocessing it was trained with (`preprocess.json`; older checkpoints lack it); the optimiser
//! and run state beside them are the trainer's. This module reads what inference needs: the pointer, the
//! configuration, the preprocessing and the weights.

use std::fs;
use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::Bytes;
use dggt_data::Preprocess;
use dggt_model::ModelConfig;

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

/// The checkpoint `latest` points to under `root` (`run/checkpoints`), if any. When that folder is incomplete
/// (a run killed while rewriting it), the newest complete `step-*` folder instead.
pub fn latest(root: &Path) -> Result<Option<PathBuf>, InferError> {
    let pointer = root.join(LATEST);
    if !pointer.exists() {
        return Ok(None);
    }
    let name = fs::read_to_string(&pointer).map_err(|e| InferError::checkpoint(&pointer, e))?;
    let dir = root.join(name.trim());
    if dir.join(STATE_FILE).is_file() {
        return Ok(Some(dir));
    }
    match newest_complete(root)? {
        Some(complete) => {
            tracing::warn!(incomplete = %dir.display(), using = %complete.display(), "`latest` names an incomplete checkpoint");
            Ok(Some(complete))
        }
        None => Err(InferError::checkpoint(&dir, format!("`{LATEST}` points to a folder without {STATE_FILE}"))),
    }
}

/// The `step-*` folder under `root` with the highest step that holds a run state.
fn newest_complete(root: &Path) -> Result<Option<PathBuf>, InferError> {
    let entries = fs::read_dir(root).map_err(|e| InferError::checkpoint(root, e))?;
    let mut complete: Vec<PathBuf> = entries
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("step-")))
        .filter(|p| p.join(STATE_FILE).is_file())
        .collect();
    complete.sort();
    Ok(complete.pop())
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
    let path = dir.join(MODEL_FILE);
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(read(&path)?))
        .map_err(|e| InferError::checkpoint(&path, format!("{e:?}")))?;
    model.try_load_record(record).map_err(|e| InferError::checkpoint(&path, format!("does not fit the network: {e:?}")))
}

/// The checkpoint folder of a `step-N` folder, a run's `checkpoints/` folder or a run folder.
pub fn checkpoint_dir(path: &Path) -> Result<PathBuf, InferError> {
    if path.join(MODEL_CONFIG_FILE).is_file() {
        return Ok(path.to_path_buf());
    }
    for root in [path.to_path_buf(), path.join("checkpoints")] {
        if root.join(LATEST).is_file()
            && let Some(dir) = latest(&root)?
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
