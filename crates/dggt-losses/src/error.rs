//! The error type of this crate: weight files that cannot be read or lack a tensor the networks need, and
//! inputs whose shapes do not fit a loss or metric.
//!
//! Loading never panics on a bad file: every missing or wrongly shaped tensor is reported with the file, the
//! tensor's name (all accepted spellings) and the shape the network expects.

use thiserror::Error;

/// Errors of weight loading and of input checks.
#[derive(Debug, Error)]
pub enum LossError {
    /// The file could not be opened or parsed, or has an unknown extension.
    #[error("reading weights from {path}: {message}")]
    WeightsFile { path: String, message: String },
    /// None of the accepted names of a tensor is in the file.
    #[error("{path}: tensor '{name}' (shape {expected:?}) is missing{}", aliases_note(.aliases))]
    MissingTensor { path: String, name: String, aliases: Vec<String>, expected: Vec<usize> },
    /// The tensor is present but its shape differs from the network's.
    #[error("{path}: tensor '{name}' has shape {found:?}, expected {expected:?}")]
    ShapeMismatch { path: String, name: String, expected: Vec<usize>, found: Vec<usize> },
    /// The tensor's bytes could not be read or converted to f32.
    #[error("{path}: tensor '{name}' could not be read: {message}")]
    TensorData { path: String, name: String, message: String },
    /// Input tensors or buffers whose shapes do not fit (different shapes, wrong channel count, too small).
    #[error("invalid input: {0}")]
    InvalidInput(String),
}

fn aliases_note(aliases: &[String]) -> String {
    if aliases.is_empty() { String::new() } else { format!(" (also looked for: {})", aliases.join(", ")) }
}
