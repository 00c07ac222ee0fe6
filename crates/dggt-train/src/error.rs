//! Training errors: each names the file, tensor or setting at fault.

use std::path::PathBuf;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum TrainError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("configuration {path}: {detail}")]
    Config { path: PathBuf, detail: String },
    #[error("checkpoint {path}: {detail}")]
    Checkpoint { path: PathBuf, detail: String },
    #[error(transparent)]
    Run(#[from] dggt_run::RunError),
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Model(#[from] dggt_model::ModelError),
    #[error(transparent)]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
    /// A configuration value out of its range, or settings that contradict each other.
    #[error("{setting}: {detail}")]
    Setting { setting: &'static str, detail: String },
    #[error(transparent)]
    Infer(#[from] dggt_infer::InferError),
    /// A checkpoint folder that cannot be read, or whose files do not match its manifest.
    #[error(transparent)]
    CheckpointFolder(#[from] dggt_checkpoint::CheckpointError),
    #[error(transparent)]
    Objective(#[from] dggt_objective::ObjectiveError),
    /// A run given no device to train on.
    #[error("devices: training needs at least one device")]
    NoDevice,
    /// A resume whose `run.seed` is not the checkpoint's.
    #[error("resume: the checkpoint's seed {checkpoint} differs from run.seed {configured}")]
    SeedChanged { checkpoint: u64, configured: u64 },
    /// A resume whose configuration describes another network than the checkpoint's.
    #[error(
        "cannot resume from {}: the configuration describes another network ({}); the weights fix the network, so \
         resume with the checkpoint's settings or start a new run in another folder",
        checkpoint.display(),
        changes.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")
    )]
    ArchitectureChanged { checkpoint: PathBuf, changes: Vec<Change> },
    /// A resume whose configuration changes what the network sees (preprocessing, sampler), unallowed.
    #[error(
        "cannot resume from {}: the configuration changes what the network sees ({}); resume with the \
         checkpoint's settings, allow each change with --allow-changed KEY, or start a new run in another folder",
        checkpoint.display(),
        changes.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")
    )]
    InputsChanged { checkpoint: PathBuf, changes: Vec<Change> },
    /// The single scene of a run (`data.scene`) that cannot be indexed.
    #[error("data.scene {}: {reason}", scene.display())]
    SceneExcluded { scene: PathBuf, reason: String },
    /// A validation frame beyond the frames of a validation scene.
    #[error(
        "data.validation: frame {frame} is outside the {frame_count} frames of {} (positions 0..{frame_count})",
        scene.display()
    )]
    ValidationFrame { frame: usize, frame_count: usize, scene: PathBuf },
    /// More samples failed to load than `data.max_bad_samples` allows.
    #[error("data: {failed} samples failed to load, more than data.max_bad_samples = {limit}; the last: {last}")]
    TooManyBadSamples { failed: u64, limit: u64, last: String },
    /// The sample stream stopped before the run had its samples.
    #[error("data stream: ended early")]
    StreamEnded,
    /// A validation render's comparison image that cannot be written.
    #[error("{}: {detail}", path.display())]
    Comparison { path: PathBuf, detail: String },
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    /// A validation depth score that cannot be computed.
    #[error("validation D-RMSE: {0}")]
    DepthScore(dggt_metrics::MetricError),
    /// A sum or broadcast across the ranks of the job failed.
    #[error("across ranks: {0}")]
    Collective(#[from] dggt_collective::CollectiveError),
    /// Another rank of the job failed (its own message says how); this one stops with it.
    #[error("another rank failed while {what} (see its message); this rank stops too")]
    RankFailed { what: &'static str },
    /// Ranks whose weights differ from rank 0's after the same steps: the run is no longer one run.
    #[error(
        "{ranks} rank(s) hold weights that differ from rank 0's (checksum {checksum:016x}): the ranks were \
         expected to take identical steps"
    )]
    RanksOutOfStep { ranks: usize, checksum: u64 },
    /// A validation pass's picture for a watcher that cannot be made.
    #[error("validation snapshot: {0}")]
    Snapshot(String),
    /// An error of a validation pass, with the step it validated.
    #[error("validation at step {step}: {source}")]
    Validation { step: u64, source: Box<TrainError> },
}

/// A setting whose value differs between a checkpoint and the configuration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Change {
    /// Its dotted name (`model.pixel_skip`, `optim.lr`; for an older checkpoint the network configuration's
    /// own names, `network.dpt.pixel_skip`).
    pub setting: String,
    pub checkpoint: String,
    pub configured: String,
}

impl std::fmt::Display for Change {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} is {} in the checkpoint, {} in the configuration", self.setting, self.checkpoint, self.configured)
    }
}
