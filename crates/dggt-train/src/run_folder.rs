//! A run's output folder: what a training run writes there, and the rule that a fresh run never starts over
//! another run's files. Those files are a user's work (weights, optimiser state, metrics, validation renders);
//! a run that finds them either continues them ([`Start::Resume`](crate::Start::Resume)) or is refused, so that
//! pruning, the `latest` pointer and the metrics of two runs never mix.
//!
//! The scene index (`scene-index.json`) is not among them: it is a cache, checked against the scenes on every
//! use and rebuilt when stale, and a dry run writes it before any step.

use std::path::Path;

use crate::error::TrainError;

/// The checkpoint folders (`step-NNNNNNNN/` and the `latest` pointer).
pub const CHECKPOINTS: &str = "checkpoints";
/// One JSON record per training step and validation.
pub const METRICS: &str = "metrics.jsonl";
/// Validation renders, one folder per validated step.
pub const VALIDATION: &str = "validation";
/// The cached scene index.
pub const SCENE_INDEX: &str = "scene-index.json";

/// Everything of a run's own in its output folder.
pub const RUN_ENTRIES: [&str; 3] = [CHECKPOINTS, METRICS, VALIDATION];

/// The entries of [`RUN_ENTRIES`] that exist in `dir` (none for a missing or empty folder).
pub fn run_entries(dir: &Path) -> Vec<&'static str> {
    RUN_ENTRIES.into_iter().filter(|entry| dir.join(entry).exists()).collect()
}

/// Refuses `dir` as the output folder of a fresh run when it holds a run's files.
pub fn ensure_no_run(dir: &Path) -> Result<(), TrainError> {
    let found = run_entries(dir);
    if found.is_empty() {
        return Ok(());
    }
    Err(TrainError::RunExists { dir: dir.to_path_buf(), found })
}
