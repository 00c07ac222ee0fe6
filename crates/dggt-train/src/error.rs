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
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
    /// A configuration value out of its range, or settings that contradict each other.
    #[error("{setting}: {detail}")]
    Setting { setting: &'static str, detail: String },
    #[error("{0}")]
    Infer(#[from] dggt_infer::InferError),
    #[error("{0}")]
    Objective(#[from] dggt_objective::ObjectiveError),
}
