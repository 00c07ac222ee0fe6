//! Errors of an evaluation; each names the scene, file or setting at fault.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
    #[error("scene {}: {detail}", path.display())]
    Scene { path: PathBuf, detail: String },
    #[error("{}: {detail}", path.display())]
    File { path: PathBuf, detail: String },
    #[error("scene {}: {source}", path.display())]
    InScene { path: PathBuf, source: Box<EvalError> },
    #[error(transparent)]
    Infer(#[from] dggt_infer::InferError),
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Scene3d(#[from] dggt_scene::SceneError),
    #[error(transparent)]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
}

impl EvalError {
    pub(crate) fn invalid(what: impl Into<String>, detail: impl Into<String>) -> Self {
        Self::Invalid { what: what.into(), detail: detail.into() }
    }

    pub(crate) fn scene(path: &Path, detail: impl Into<String>) -> Self {
        Self::Scene { path: path.to_path_buf(), detail: detail.into() }
    }

    pub(crate) fn file(path: &Path, detail: impl Into<String>) -> Self {
        Self::File { path: path.to_path_buf(), detail: detail.into() }
    }

    /// This error, said to concern scene `path` (unless it already names the scene).
    pub(crate) fn in_scene(self, path: &Path) -> Self {
        match self {
            Self::Scene { .. } | Self::InScene { .. } => self,
            other => Self::InScene { path: path.to_path_buf(), source: Box::new(other) },
        }
    }
}
