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
    #[error("{0}")]
    Data(#[from] dggt_data::DataError),
    #[error("{0}")]
    Model(#[from] dggt_model::ModelError),
    #[error("{0}")]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
    /// A configuration value out of its range, or settings that contradict each other.
    #[error("{setting}: {detail}")]
    Setting { setting: &'static str, detail: String },
    #[error("{0}")]
    Infer(#[from] dggt_infer::InferError),
    #[error("{0}")]
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
}
