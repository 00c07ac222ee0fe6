//! Checkpoints: everything a run needs to continue exactly as if it had not stopped.
//!
//! The network's half (its weights, its configuration and the `latest` pointer) is read by
//! [`dggt_infer::checkpoint`], which inference shares; this module adds the optimiser and run state and writes
//! all of it.
//!
//! A checkpoint is a folder `checkpoints/step-NNNNNNNN/` holding the network (`model.bpk`, burnpack, parameter
//! ids included so the optimiser state stays attached), the AdamW state (`optimizer.bpk`), the network's
//! configuration (`model.json`) and the run state (`state.json`: the next step, seed and counters). The
//! learning-rate schedule is a function of the step and the sampler draws sample `k` from `(seed, k)`, so no
//! random-generator state needs saving. Every file is written through a temporary file and a rename, and the
//! `checkpoints/latest` pointer is replaced last: an interrupted write leaves the previous checkpoint current.

use std::fs;
use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::ModuleOptimizer;
use burn::tensor::Bytes;
use dggt_data::io::write_atomically;
pub use dggt_infer::checkpoint::{
    LATEST, MODEL_CONFIG_FILE, MODEL_FILE, STATE_FILE, latest, load_model, read_model_config,
};
use dggt_model::{Dggt, ModelConfig};
use serde::{Deserialize, Serialize};

use crate::error::TrainError;

/// The counters of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunState {
    /// The next optimiser step to run.
    pub step: u64,
    pub seed: u64,
    /// Steps skipped for a non-finite loss or gradient.
    pub skipped_steps: u64,
    /// Training seconds before this checkpoint (summed over resumed segments).
    pub elapsed_s: f64,
    /// Samples that failed to load and were replaced.
    #[serde(default)]
    pub bad_samples: u64,
}

/// The optimiser's state in a checkpoint folder.
const OPTIMIZER_FILE: &str = "optimizer.bpk";

fn checkpoint_error(path: &Path, detail: impl ToString) -> TrainError {
    TrainError::Checkpoint { path: path.to_path_buf(), detail: detail.to_string() }
}

/// Writes a checkpoint under `root` (`run/checkpoints`) and points `latest` at it; keeps the newest `keep`.
pub fn save(
    root: &Path,
    model: &Dggt,
    config: &ModelConfig,
    optimizer: &ModuleOptimizer,
    state: &RunState,
    keep: usize,
) -> Result<PathBuf, TrainError> {
    let name = format!("step-{:08}", state.step);
    let dir = root.join(&name);
    let write = |file: &str, bytes: &[u8]| -> Result<(), TrainError> {
        write_atomically(&dir.join(file), bytes).map_err(|e| checkpoint_error(&dir.join(file), e))
    };
    let model_bytes = model.clone().into_record().into_bytes().map_err(|e| checkpoint_error(&dir, format!("{e:?}")))?;
    write(MODEL_FILE, &model_bytes)?;
    let optim_bytes = optimizer.into_bytes().map_err(|e| checkpoint_error(&dir, format!("{e:?}")))?;
    write(OPTIMIZER_FILE, &optim_bytes)?;
    write(MODEL_CONFIG_FILE, serde_json::to_string_pretty(config).expect("configs serialise").as_bytes())?;
    write(STATE_FILE, serde_json::to_string_pretty(state).expect("states serialise").as_bytes())?;
    write_atomically(&root.join(LATEST), name.as_bytes()).map_err(|e| checkpoint_error(&root.join(LATEST), e))?;
    prune(root, keep.max(1))?;
    Ok(dir)
}

fn prune(root: &Path, keep: usize) -> Result<(), TrainError> {
    let mut steps: Vec<PathBuf> = fs::read_dir(root)
        .map_err(|e| checkpoint_error(root, e))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.is_dir() && p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("step-")))
        .collect();
    steps.sort();
    let excess = steps.len().saturating_sub(keep);
    for old in &steps[..excess] {
        fs::remove_dir_all(old).map_err(|e| checkpoint_error(old, e))?;
    }
    Ok(())
}

/// A loaded checkpoint.
pub struct Loaded {
    pub model: Dggt,
    pub config: ModelConfig,
    pub optimizer: ModuleOptimizer,
    pub state: RunState,
}

fn read(path: &Path) -> Result<Vec<u8>, TrainError> {
    fs::read(path).map_err(|e| checkpoint_error(path, e))
}

/// Loads everything; `model` and `optimizer` are fresh ones built from the stored configuration.
pub fn load(dir: &Path, model: Dggt, optimizer: ModuleOptimizer) -> Result<Loaded, TrainError> {
    let config = read_model_config(dir)?;
    let model = load_model(dir, model)?;
    let path = dir.join(OPTIMIZER_FILE);
    let optimizer = optimizer
        .from_bytes(Bytes::from_bytes_vec(read(&path)?))
        .map_err(|e| checkpoint_error(&path, format!("{e:?}")))?;
    let path = dir.join(STATE_FILE);
    let state: RunState = serde_json::from_slice(&read(&path)?).map_err(|e| checkpoint_error(&path, e))?;
    Ok(Loaded { model, config, optimizer, state })
}
