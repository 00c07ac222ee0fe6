//! Errors of a training run's machinery: each names the file, setting or step at fault.

use std::path::PathBuf;

use thiserror::Error;

use crate::finite::NonFinite;

#[derive(Debug, Error)]
pub enum RunError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    /// A checkpoint file or folder that cannot be written or read, or holds something unexpected.
    #[error("checkpoint {path}: {detail}")]
    Checkpoint { path: PathBuf, detail: String },
    /// A metrics file that cannot be rewritten.
    #[error("{path}: {detail}")]
    Metrics { path: PathBuf, detail: String },
    /// A configuration value out of its range.
    #[error("{setting}: {detail}")]
    Setting { setting: &'static str, detail: String },
    /// A checkpoint folder that cannot be read or written, or whose files do not match its manifest.
    #[error(transparent)]
    CheckpointFolder(#[from] dggt_checkpoint::CheckpointError),
    /// A fresh run asked to write where another run's files are.
    #[error("{} already holds a training run ({}); a new run would overwrite it", dir.display(), found.join(", "))]
    RunExists { dir: PathBuf, found: Vec<&'static str> },
    /// Too many steps in a row made no update (the divergence check).
    #[error(
        "training diverged: the {} steps {first_step}..={last_step} in a row made no update (the last: \
         {last_failure}); the weights are those from before step {first_step}. Lower the learning rate (optim.lr \
         is {lr}, and any optim.groups rate), set or lower optim.clip_grad_norm, or lengthen optim.warmup_steps, \
         then continue from the last checkpoint with --resume (optim.max_failed_steps_in_a_row = {limit} failed \
         steps in a row stop a run)",
        last_step + 1 - first_step
    )]
    Diverged { first_step: u64, last_step: u64, last_failure: String, lr: f64, limit: u64 },
    /// A checkpoint that would hold non-finite values is not written.
    #[error(
        "checkpoint {}: not written, the {non_finite} holds non-finite values (the earlier checkpoints are kept)",
        dir.display()
    )]
    NonFiniteCheckpoint { dir: PathBuf, non_finite: NonFinite },
}
