//! Errors of an evaluation; each names the scene, file or setting at fault.

use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A command-line option's value is out of its range or contradicts the protocol.
    #[error("{option}: {detail}")]
    Option { option: &'static str, detail: String },
    /// The checkpoint's network has no Gaussian head: nothing can be rendered to score.
    #[error("checkpoint {}: the network has no Gaussian head: there is nothing to render", checkpoint.display())]
    NoGaussianHead { checkpoint: PathBuf },
    /// The refiner's reference view was asked of a camera without input views.
    #[error("refiner reference: no input view of camera {camera}")]
    NoReferenceView { camera: usize },
    /// The diffusion refiner failed while `doing` (loading it, refining a render).
    #[error("{doing}")]
    Refine { doing: String, source: dggt_refine::RefineError },
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
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
    /// A crop of the moving objects could not be written.
    #[error("writing the crops {}", path.display())]
    Crops { path: PathBuf, source: dggt_formats::FormatError },
}

impl EvalError {
    pub(crate) fn option(option: &'static str, detail: impl Into<String>) -> Self {
        Self::Option { option, detail: detail.into() }
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
