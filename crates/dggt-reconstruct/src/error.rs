//! Errors of a reconstruction; each names the file or setting at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum ReconstructError {
    #[error("{}: {detail}", path.display())]
    Input { path: PathBuf, detail: String },
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
    #[error("{0}")]
    OutputTooLarge(crate::volume::OutputTooLarge),
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Scene(#[from] dggt_scene::SceneError),
    #[error(transparent)]
    Infer(#[from] dggt_infer::InferError),
    #[error(transparent)]
    Export(#[from] dggt_export::ExportError),
}

impl ReconstructError {
    pub(crate) fn input(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        Self::Input { path: path.into(), detail: detail.into() }
    }

    pub(crate) fn invalid(what: impl Into<String>, detail: impl Into<String>) -> Self {
        Self::Invalid { what: what.into(), detail: detail.into() }
    }
}
