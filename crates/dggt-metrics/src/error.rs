//! Why a metric has no value.

/// Why a metric has no value: the inputs cannot be scored.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricError {
    #[error("{metric}: no points to score")]
    Empty { metric: &'static str },
    #[error("{metric}: {predicted} predicted values for {truth} true ones")]
    LengthMismatch { metric: &'static str, predicted: usize, truth: usize },
    #[error("{metric}: non-finite {which} value at point {index}")]
    NonFinite { metric: &'static str, which: &'static str, index: usize },
    /// A true depth of zero or less, which no relative error can be taken against.
    #[error("{metric}: true depth {value} at point {index}, expected a positive depth")]
    NonPositiveTruth { metric: &'static str, index: usize, value: f32 },
    /// Image buffers that do not hold the image's values.
    #[error(
        "{metric}: image buffers of {rendered} and {truth} values for a non-empty {height}x{width}x{channels} image"
    )]
    ImageBuffers { metric: &'static str, rendered: usize, truth: usize, height: usize, width: usize, channels: usize },
    /// Images smaller than the SSIM window.
    #[error("SSIM needs images of at least {window}x{window}, got {height}x{width}")]
    TooSmall { window: usize, height: usize, width: usize },
    /// Rendered and true image batches of different shapes.
    #[error("image batches differ: rendered {rendered:?}, true {truth:?}")]
    BatchShapes { rendered: [usize; 4], truth: [usize; 4] },
    /// Image values that could not be read back as `f32`.
    #[error("reading the {which} images: {detail}")]
    Unreadable { which: &'static str, detail: String },
}

/// Rejects paired inputs of different lengths, or none.
pub(crate) fn check_lengths(metric: &'static str, predicted: usize, truth: usize) -> Result<(), MetricError> {
    if predicted != truth {
        return Err(MetricError::LengthMismatch { metric, predicted, truth });
    }
    if truth == 0 {
        return Err(MetricError::Empty { metric });
    }
    Ok(())
}
