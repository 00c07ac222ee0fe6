//! Errors of model construction and weight loading.

use thiserror::Error;

#[derive(Debug, Error)]
pub enum ModelError {
    #[error("invalid model configuration: {0}")]
    Config(String),
    #[error("reading {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("reading weights from {path}: {message}")]
    WeightsFile { path: String, message: String },
    #[error(
        "weight '{name}' has shape {found:?} in the checkpoint (burn layout: Linear weights transposed) but the network expects {expected:?}"
    )]
    ShapeMismatch { name: String, expected: Vec<usize>, found: Vec<usize> },
    #[error("{} checkpoint tensor(s) have shapes the network does not expect: {}", .0.len(), first_names(.0))]
    ShapeMismatches(Vec<String>),
    #[error("weight '{name}' could not be applied: {message}")]
    WeightApply { name: String, message: String },
    #[error("the checkpoint lacks {} tensor(s) the network needs: {}", .0.len(), .0.join(", "))]
    MissingWeights(Vec<String>),
    #[error(transparent)]
    Safetensors(#[from] crate::safetensors_file::SafetensorsError),
    #[error("input image size {height}x{width} is not a multiple of the patch size {patch}")]
    ImageSize { height: usize, width: usize, patch: usize },
}

/// The first twenty of many names, and how many more there are.
fn first_names(names: &[String]) -> String {
    const SHOWN: usize = 20;
    let shown = names.iter().take(SHOWN).cloned().collect::<Vec<_>>().join("; ");
    match names.len().saturating_sub(SHOWN) {
        0 => shown,
        more => format!("{shown}; and {more} more"),
    }
}
