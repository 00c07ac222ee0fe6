//! Errors for input the rasteriser cannot interpret: buffers or tensors of the wrong length, shape or element
//! type, invalid cameras or settings.
//!
//! Per-Gaussian problems (NaN parameters, degenerate shapes) are not errors: such Gaussians are culled and
//! counted in [`CullStats`](crate::CullStats), so one bad splat cannot stop a training step.

/// Why a rasteriser call was refused. Each variant names the buffer or value and what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SplatError {
    #[error("`{tensor}` has {actual} values, expected {expected}")]
    Shape { tensor: &'static str, expected: String, actual: usize },
    #[error("`{tensor}` has shape {actual:?}, expected {expected}")]
    TensorShape { tensor: &'static str, expected: String, actual: Vec<usize> },
    #[error("`{tensor}` has element type {actual}, expected f32")]
    ElementType { tensor: &'static str, actual: String },
    #[error("`{what}` contains a non-finite value (NaN or infinity)")]
    NonFinite { what: &'static str },
    #[error("invalid camera {view}: {detail}")]
    InvalidView { view: usize, detail: String },
    #[error("invalid raster settings: {detail}")]
    InvalidSettings { detail: String },
    #[error("the forward result does not belong to these inputs: {detail}")]
    ForwardMismatch { detail: String },
}

/// Checks that `tensor` holds `rows x row_len` values.
pub(crate) fn expect_len(
    tensor: &'static str,
    values: &[f32],
    rows: usize,
    row_len: usize,
    shape: &str,
) -> Result<(), SplatError> {
    let expected = rows * row_len;
    if values.len() != expected {
        return Err(SplatError::Shape { tensor, expected: format!("{expected} ({shape})"), actual: values.len() });
    }
    Ok(())
}
