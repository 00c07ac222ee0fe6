//! Training errors: each names the file, tensor or setting at fault.

use std::path::PathBuf;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum TrainError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("configuration {path}: {detail}")]
    Config { path: PathBuf, detail: String },
    #[error("checkpoint {path}: {detail}")]
    Checkpoint { path: PathBuf, detail: String },
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Model(#[from] dggt_model::ModelError),
    #[error(transparent)]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
    /// A configuration value out of its range, or settings that contradict each other.
    #[error("{setting}: {detail}")]
    Setting { setting: &'static str, detail: String },
    #[error(transparent)]
    Infer(#[from] dggt_infer::InferError),
    #[error(transparent)]
    Objective(#[from] dggt_objective::ObjectiveError),
    /// A fresh run asked to write where another run's files are.
    #[error("{} already holds a training run ({}); a new run would overwrite it", dir.display(), found.join(", "))]
    RunExists { dir: PathBuf, found: Vec<&'static str> },
    /// A resume whose configuration describes another network than the checkpoint's.
    #[error(
        "cannot resume from {}: the configuration describes another network ({}); the weights fix the network, so \
         resume with the checkpoint's settings or start a new run in another folder",
        checkpoint.display(),
        changes.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")
    )]
    ArchitectureChanged { checkpoint: PathBuf, changes: Vec<crate::resume::Change> },
    /// Too many steps in a row made no update ([`crate::divergence`]).
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
    NonFiniteCheckpoint { dir: PathBuf, non_finite: crate::finite::NonFinite },
    /// An error of a validation pass, with the step it validated.
    #[error("validation at step {step}: {source}")]
    Validation { step: u64, source: Box<TrainError> },
}
