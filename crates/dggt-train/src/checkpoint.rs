//! The DGGT trainer's checkpoints: a run's checkpoint folder ([`dggt_run::checkpoint`]) with the files that
//! say how its network was made: the network's configuration (`model.json`), the input preprocessing it was
//! trained with (`preprocess.json`, inference's default) and the `[model]` and `[optim]` sections as
//! configured (`training.json`, which a resume compares with its own: [`resume`](crate::resume)).
//!
//! The network's half (its weights, its configuration and the `latest` pointer) is read by
//! [`dggt_checkpoint`], which inference shares.

use std::path::{Path, PathBuf};

pub use dggt_checkpoint::{MODEL_CONFIG_FILE, PREPROCESS_FILE, read_model_config, read_preprocess};
use dggt_data::Preprocess;
use dggt_model::{Dggt, ModelConfig};
use dggt_run::Optimizer;
pub use dggt_run::checkpoint::Weights;
use dggt_run::checkpoint::{RunState, load_trained, read_state, save_folder};
use serde::Serialize;

use crate::error::TrainError;
use crate::resume::{ConfiguredSections, TRAINING_FILE};

/// What a checkpoint records beside the weights about how its network was made.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The network's configuration (`model.json`).
    pub model: ModelConfig,
    /// The input preprocessing of training (`preprocess.json`).
    pub preprocess: Preprocess,
    /// The `[model]` and `[optim]` sections (`training.json`).
    pub configured: ConfiguredSections,
}

/// Writes a checkpoint under `root` (`run/checkpoints`) and points `latest` at it; keeps the newest `keep`.
pub fn save(
    root: &Path,
    weights: Weights<'_, Dggt>,
    settings: &Settings,
    optimizer: &Optimizer,
    state: &RunState,
    keep: usize,
) -> Result<PathBuf, TrainError> {
    fn json(value: &impl Serialize) -> String {
        serde_json::to_string_pretty(value).expect("settings serialise")
    }
    let files = [
        (MODEL_CONFIG_FILE, json(&settings.model)),
        (PREPROCESS_FILE, json(&settings.preprocess)),
        (TRAINING_FILE, json(&settings.configured)),
    ];
    let extra: Vec<(&str, &[u8])> = files.iter().map(|(name, text)| (*name, text.as_bytes())).collect();
    Ok(save_folder(root, weights, optimizer, state, keep, &extra)?)
}

/// A loaded checkpoint.
pub struct Loaded {
    /// The trained weights.
    pub model: Dggt,
    /// Their average, when the run kept one ([`dggt_run::average`]).
    pub average: Option<Dggt>,
    pub config: ModelConfig,
    pub state: RunState,
}

/// Loads the trained network (and its average, if any) into `model` (built from the stored configuration) and
/// the run state; the optimiser loads its own file ([`dggt_run::checkpoint::optimizer_file`]).
pub fn load(dir: &Path, model: Dggt) -> Result<Loaded, TrainError> {
    let config = read_model_config(dir)?;
    let (model, average) = load_trained(dir, model)?;
    let state = read_state(dir)?;
    Ok(Loaded { model, average, config, state })
}
