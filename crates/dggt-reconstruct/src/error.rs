//! Errors of a reconstruction; each names the file or setting at fault.

use std::path::PathBuf;

use crate::volume::OutputTooLarge;

#[derive(Debug, thiserror::Error)]
pub enum ReconstructError {
    #[error("{}: {detail}", path.display())]
    Input { path: PathBuf, detail: String },
    /// A command-line option's value is out of its range.
    #[error("{option}: {detail}")]
    Option { option: &'static str, detail: String },
    /// A render was asked of a camera that has no input view to place it.
    #[error("camera {camera}: no input view")]
    NoInputView { camera: usize },
    #[error("{0}")]
    OutputTooLarge(OutputTooLarge),
    /// A value about to be written is not finite (NaN or infinite); nothing is written.
    #[error("{}: {what} element {element} is {value}, not finite: the file is not written", path.display())]
    NonFinite { path: PathBuf, what: String, element: usize, value: f64 },
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Scene(#[from] dggt_scene::SceneError),
    #[error(transparent)]
    Infer(#[from] dggt_infer::InferError),
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    #[error(transparent)]
    Format(#[from] dggt_formats::FormatError),
}

impl ReconstructError {
    pub(crate) fn input(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        Self::Input { path: path.into(), detail: detail.into() }
    }

    pub(crate) fn option(option: &'static str, detail: impl Into<String>) -> Self {
        Self::Option { option, detail: detail.into() }
    }
}
