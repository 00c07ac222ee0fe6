//! Errors of training the refiner: each names the file, tensor or setting at fault.

use std::path::PathBuf;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum RefineTrainError {
    #[error(transparent)]
    Refine(#[from] dggt_refine::RefineError),
    #[error(transparent)]
    Run(#[from] dggt_run::RunError),
    #[error(transparent)]
    Safetensors(#[from] dggt_model::safetensors_file::SafetensorsError),
    /// A checkpoint folder that cannot be read, or whose files do not match its manifest.
    #[error(transparent)]
    CheckpointFolder(#[from] dggt_checkpoint::CheckpointError),
    #[error(transparent)]
    Objective(#[from] dggt_objective::ObjectiveError),
    #[error(transparent)]
    Data(#[from] dggt_data::DataError),
    #[error(transparent)]
    Loss(#[from] dggt_losses::LossError),
    #[error(transparent)]
    Metric(#[from] dggt_metrics::MetricError),
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("configuration {path}: {detail}")]
    Config { path: PathBuf, detail: String },
    /// A configuration value out of its range, or settings that contradict each other.
    #[error("{setting}: {detail}")]
    Setting { setting: &'static str, detail: String },
    /// A file of clean images (synthetic pairs' source) that is missing an image or holds one of the wrong
    /// kind.
    #[error("{}: {detail}", path.display())]
    ImageFile { path: PathBuf, detail: String },
    /// A pairs file, or a folder of them, that cannot be read or written as one.
    #[error("{}: {detail}", path.display())]
    PairFile { path: PathBuf, detail: String },
    /// The prompt's token file that does not hold the token ids.
    #[error("{}: {detail}", path.display())]
    PromptTokens { path: PathBuf, detail: String },
    /// A pair asked for beyond those there are.
    #[error("pairs: {kind}pair {index} of {count}")]
    NoSuchPair { kind: PairKind, index: usize, count: usize },
    /// Images of a batch that cannot be stacked.
    #[error("batch: {0}")]
    Batch(String),
    /// A Difix checkpoint's LoRA factors that do not fit the refiner.
    #[error("{}: LoRA '{module}': {detail}", checkpoint.display())]
    Lora { checkpoint: PathBuf, module: String, detail: String },
    /// A parameter the trained refiner's index names that it does not hold.
    #[error("{name}: {detail}")]
    MissingParameter { name: String, detail: &'static str },
    /// A rendered target view with no input view of its camera to take the reference from.
    #[error("sample {sample}: no input view of camera {camera} to take the reference from")]
    NoReference { sample: u64, camera: usize },
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    /// More training pairs failed to read than `pairs.max_bad_pairs` allows.
    #[error("pairs.max_bad_pairs: {failed} pairs could not be read (at most {limit} may fail); the last: {last}")]
    TooManyBadPairs { failed: u64, limit: u64, last: String },
    /// None of the training pairs can be read.
    #[error("pairs: none of the {count} training pairs can be read")]
    NoTrainingPairReadable { count: usize },
    /// None of the held-out pairs can be read.
    #[error("pairs.held_out: no held-out pair can be read")]
    NoHeldOutPairReadable,
    /// An error of a validation pass, with the step it validated.
    #[error("validation at step {step}: {source}")]
    Validation { step: u64, source: Box<RefineTrainError> },
}

/// Which of a run's pairs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PairKind {
    /// Any pair of a source, counted over all of them.
    Any,
    /// A pair trained on.
    Training,
    /// A pair held out for validation.
    HeldOut,
}

impl std::fmt::Display for PairKind {
    /// The kind as it prefixes "pair" in a message (`training `, `held-out `, or nothing).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Any => "",
            Self::Training => "training ",
            Self::HeldOut => "held-out ",
        })
    }
}
