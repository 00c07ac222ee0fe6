//! Errors of building a batch and computing its objective; each names the view, tensor or file at fault.

use dggt_scene::SceneError;

#[derive(Debug, thiserror::Error)]
pub enum ObjectiveError {
    /// The network cannot compute this objective (no aggregator layer, no Gaussian head to render with).
    #[error("model: {0}")]
    Unsupported(&'static str),
    /// A training sample has no input view.
    #[error("sample of step {step}: no input views")]
    NoInputViews { step: u64 },
    /// A sample's views are not all of one size.
    #[error("view (frame {frame}, camera {camera}): size {size} differs from the first input's {first}")]
    ViewSize { frame: usize, camera: usize, size: dggt_geom::ImageSize, first: dggt_geom::ImageSize },
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    #[error(transparent)]
    Infer(#[from] dggt_infer::InferError),
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Model(#[from] dggt_model::ModelError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
    #[error(transparent)]
    Geom(#[from] dggt_geom::GeomError),
}

impl ObjectiveError {
    /// Whether the network put out a non-finite value (a depth that overflowed, say): the sample is lost, not the
    /// run.
    pub fn is_non_finite_output(&self) -> bool {
        matches!(
            self,
            Self::Scene(SceneError::NonFinite { .. })
                | Self::Infer(dggt_infer::InferError::Scene(SceneError::NonFinite { .. }))
        )
    }
}
