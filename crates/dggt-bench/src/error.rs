//! Errors of a benchmark run, each naming the file, option or stage it concerns.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A setting (a command-line option, a knob of a sweep) whose value is not understood or out of range.
    #[error("{setting}: {detail}")]
    Setting { setting: &'static str, detail: String },
    /// Record files of different implementations or builds cannot be merged into one table.
    #[error("record files: cannot merge `{other}` records into `{first}` ones")]
    MixedRecords { first: String, other: String },
    /// Something a workload needs is not there (a layer, a head, a gradient, a reference run).
    #[error("{0}")]
    Missing(&'static str),
    /// A panic inside a measured run (some backends panic when out of device memory).
    #[error("{doing} panicked: {message}")]
    Panicked { doing: &'static str, message: String },
    /// A training step of the train-step workload did not complete.
    #[error("{doing}")]
    Train { doing: &'static str, source: Box<dggt_train::TrainError> },
    /// A training step was skipped (a non-finite loss, say), so it cannot be timed.
    #[error("step skipped: {0}")]
    StepSkipped(String),
    /// The diffusion refiner failed while `doing`.
    #[error("{doing}")]
    Refine { doing: &'static str, source: Box<dggt_refine::RefineError> },
    /// The refiner's reference view was asked of a camera without input views.
    #[error("refiner reference: no input view of camera {camera}")]
    NoReferenceView { camera: usize },
    /// No temporary folder could be made for the train-step workload's run.
    #[error("cannot create a temporary scratch folder")]
    ScratchFolder(#[source] std::io::Error),
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    #[error("{}: {detail}", path.display())]
    File { path: PathBuf, detail: String },
    /// A line of a run's `metrics.jsonl` that is not a record (`line` counts from 1).
    #[error("{}, line {line}: {detail}", path.display())]
    MetricsLine { path: PathBuf, line: usize, detail: String },
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Model(#[from] dggt_model::ModelError),
    #[error(transparent)]
    Scene(#[from] dggt_scene::SceneError),
    #[error(transparent)]
    Splat(#[from] dggt_splat::SplatError),
    #[error(transparent)]
    Flow(#[from] dggt_flow_head::FlowError),
    #[error(transparent)]
    Infer(#[from] dggt_infer::InferError),
    #[error(transparent)]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
}

impl BenchError {
    // Takes any error by value, like `impl Into<String>`, so `map_err(|e| ..(path, e))` reads plainly.
    #[allow(clippy::needless_pass_by_value)]
    pub(crate) fn file(path: impl Into<PathBuf>, detail: impl ToString) -> Self {
        Self::File { path: path.into(), detail: detail.to_string() }
    }

    pub(crate) fn setting(setting: &'static str, detail: impl Into<String>) -> Self {
        Self::Setting { setting, detail: detail.into() }
    }
}
