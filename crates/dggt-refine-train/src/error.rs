//! Errors of training the refiner: each names the file, tensor or setting at fault.

use std::path::PathBuf;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum RefineTrainError {
    #[error(transparent)]
    Refine(#[from] dggt_refine::RefineError),
    #[error(transparent)]
    Train(#[from] dggt_train::TrainError),
    #[error(transparent)]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("configuration {path}: {detail}")]
    Config { path: PathBuf, detail: String },
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
    /// An error of a validation pass, with the step it validated.
    #[error("validation at step {step}: {source}")]
    Validation { step: u64, source: Box<RefineTrainError> },
}

impl RefineTrainError {
    pub(crate) fn invalid(what: impl Into<String>, detail: impl Into<String>) -> Self {
        Self::Invalid { what: what.into(), detail: detail.into() }
    }
}
