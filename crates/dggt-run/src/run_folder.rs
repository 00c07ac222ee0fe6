//! A run's output folder: what a training run writes there, how a run starts in it, and the rule that a fresh
//! run never starts over another run's files. Those files are a user's work (weights, optimiser state,
//! metrics, validation renders); a run that finds them either continues them ([`Start::Resume`]) or is
//! refused, so that pruning, the `latest` pointer and the metrics of two runs never mix.
//!
//! Caches a trainer keeps beside them (the DGGT trainer's scene index) are not among them.

use std::path::Path;

use crate::error::RunError;

/// The checkpoint folders (`step-NNNNNNNN/` and the `latest` pointer).
pub const CHECKPOINTS: &str = "checkpoints";
/// One JSON record per training step and validation.
pub const METRICS: &str = "metrics.jsonl";
/// Validation renders, one folder per validated step.
pub const VALIDATION: &str = "validation";

/// How a run starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// From the configured starting weights (or random ones), at step 0, in an output folder that holds no
    /// other run's files ([`ensure_no_run`]).
    Fresh,
    /// From the newest checkpoint in the output folder when there is one, exactly where it stopped; fresh
    /// otherwise.
    Resume,
}

/// Everything of a run's own in its output folder.
pub const RUN_ENTRIES: [&str; 3] = [CHECKPOINTS, METRICS, VALIDATION];

/// The entries of [`RUN_ENTRIES`] that exist in `dir` (none for a missing or empty folder).
pub fn run_entries(dir: &Path) -> Vec<&'static str> {
    RUN_ENTRIES.into_iter().filter(|entry| dir.join(entry).exists()).collect()
}

/// Refuses `dir` as the output folder of a fresh run when it holds a run's files.
pub fn ensure_no_run(dir: &Path) -> Result<(), RunError> {
    let found = run_entries(dir);
    if found.is_empty() {
        return Ok(());
    }
    Err(RunError::RunExists { dir: dir.to_path_buf(), found })
}
