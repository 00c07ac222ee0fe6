//! Errors of building a batch and computing its objective; each names the view, tensor or file at fault.

use dggt_scene::SceneError;

#[derive(Debug, thiserror::Error)]
pub enum ObjectiveError {
    #[error("{what}: {detail}")]
    Invalid { what: String, detail: String },
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
