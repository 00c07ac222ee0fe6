//! Errors of the inference path; each names the file, tensor or setting at fault.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum InferError {
    #[error("{}: {detail}", path.display())]
    Input { path: PathBuf, detail: String },
    #[error("checkpoint {}: {detail}", path.display())]
    Checkpoint { path: PathBuf, detail: String },
    /// A checkpoint folder whose files do not match its manifest ([`crate::checksums`]).
    #[error(
        "checkpoint {}: {damage}: the checkpoint is damaged and not used (an earlier checkpoint of the run may be \
         intact)",
        dir.display()
    )]
    DamagedCheckpoint { dir: PathBuf, damage: crate::checksums::Damage },
    #[error("configuration {}: {detail}", path.display())]
    Config { path: PathBuf, detail: String },
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Model(#[from] dggt_model::ModelError),
    #[error(transparent)]
    Scene(#[from] dggt_scene::SceneError),
    #[error(transparent)]
    Geom(#[from] dggt_geom::GeomError),
}

impl InferError {
    pub fn input(path: impl Into<PathBuf>, detail: impl Into<String>) -> Self {
        Self::Input { path: path.into(), detail: detail.into() }
    }

    pub fn invalid(what: impl Into<String>, detail: impl Into<String>) -> Self {
        Self::Invalid { what: what.into(), detail: detail.into() }
    }

    pub fn checkpoint(path: impl Into<PathBuf>, detail: impl ToString) -> Self {
        Self::Checkpoint { path: path.into(), detail: detail.to_string() }
    }
}
