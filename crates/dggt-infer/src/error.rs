//! Errors of the inference path; each names the file, tensor or setting at fault.

use std::path::PathBuf;

use crate::coverage::CoverageError;

#[derive(Debug, thiserror::Error)]
pub enum InferError {
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    #[error("{}: {detail}", path.display())]
    Input { path: PathBuf, detail: String },
    #[error("checkpoint {}: {detail}", path.display())]
    Checkpoint { path: PathBuf, detail: String },
    /// A checkpoint folder of this project's runs that cannot be read, or whose files do not match its manifest.
    #[error(transparent)]
    CheckpointFolder(#[from] dggt_checkpoint::CheckpointError),
    #[error("configuration {}: {detail}", path.display())]
    Config { path: PathBuf, detail: String },
    /// A checkpoint in the release's format that does not cover the network it is loaded into.
    #[error("checkpoint {}: {coverage}", path.display())]
    ReleaseCoverage { path: PathBuf, coverage: CoverageError },
    /// The forward pass takes one scene at a time.
    #[error("images: batch of {found}, expected 1")]
    BatchSize { found: usize },
    #[error("input cameras: {cameras} cameras for {views} input views")]
    CameraCount { cameras: usize, views: usize },
    /// A network whose aggregator has no layers, so the heads have no tokens to read.
    #[error("model: no aggregator layer")]
    NoAggregatorLayer,
    /// A glob pattern of a setting (such as `model.init_may_lack`) that does not parse.
    #[error("{setting}: {pattern:?}: {source}")]
    BadPattern {
        setting: &'static str,
        pattern: String,
        #[source]
        source: glob::PatternError,
    },
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

    // Takes any error by value, like `impl Into<String>`, so `map_err(|e| ..(path, e))` reads plainly.
    #[allow(clippy::needless_pass_by_value)]
    pub fn checkpoint(path: impl Into<PathBuf>, detail: impl ToString) -> Self {
        Self::Checkpoint { path: path.into(), detail: detail.to_string() }
    }
}
