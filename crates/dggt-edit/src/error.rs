//! Errors of editing: each names the argument or file at fault.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum EditError {
    /// An edit that cannot be carried out as written.
    #[error("{argument}: {detail}")]
    Argument { argument: String, detail: String },
    #[error(transparent)]
    Scene(#[from] dggt_scene::SceneError),
    #[error(transparent)]
    Format(#[from] dggt_formats::FormatError),
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    #[error("{}: {source}", path.display())]
    Io { path: std::path::PathBuf, source: std::io::Error },
}

impl EditError {
    pub fn argument(argument: &str, detail: impl Into<String>) -> Self {
        Self::Argument { argument: argument.into(), detail: detail.into() }
    }
}
