//! Errors of reading a refiner's model folder and checkpoint, and of running it.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum RefineError {
    #[error("reading {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    File { path: String, message: String },
    #[error("{path}: tensor '{name}' is missing")]
    MissingTensor { path: String, name: String },
    #[error("{path}: tensor '{name}' has shape {found:?}, expected {expected:?}")]
    ShapeMismatch { path: String, name: String, expected: Vec<usize>, found: Vec<usize> },
    #[error("{path}: LoRA target '{module}': {message}")]
    Lora { path: String, module: String, message: String },
    #[error("unsupported configuration in {path}: {message}")]
    Config { path: String, message: String },
    #[error(transparent)]
    Safetensors(#[from] dggt_model::safetensors_file::SafetensorsError),
    #[error(transparent)]
    ReadBack(#[from] dggt_model::host::ReadBackError),
    #[error("invalid input: {0}")]
    Input(String),
}

impl RefineError {
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Self::Io { path: path.display().to_string(), source }
    }

    pub(crate) fn file(path: &std::path::Path, message: impl Into<String>) -> Self {
        Self::File { path: path.display().to_string(), message: message.into() }
    }
}

/// A name on a command line or in a configuration that is none of the accepted ones.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("unknown {what} {text:?}: expected {expected}")]
pub struct UnknownName {
    /// What was named (`reference view`, `refiner precision`).
    pub what: &'static str,
    pub text: String,
    /// The accepted names, as a sentence.
    pub expected: &'static str,
}
