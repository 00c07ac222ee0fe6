//! One training pair of the refiner: a frame with artifacts, its ground truth and the reference view, as host
//! images, with the view a rendered one shows; and the check every image read from a file passes (float32
//! values in [0, 1]).

use crate::error::RefineTrainError;

/// A host image `[3, height, width]`, values in [0, 1].
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub height: usize,
    pub width: usize,
    pub values: Vec<f32>,
}

/// A frame with artifacts and its ground truth, the same size, with the reference view (an input view)
/// the refiner may attend to.
#[derive(Debug, Clone, PartialEq)]
pub struct Pair {
    pub render: Image,
    pub target: Image,
    pub reference: Option<Image>,
}

/// A rendered pair and the view it shows.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedPair {
    pub pair: Pair,
    /// Position in the scene's frames.
    pub frame: usize,
    pub camera: usize,
}

/// Little-endian float32 `bytes` as values, each checked to lie in [0, 1] (not a number fails too); `error`
/// makes the error naming them from what is wrong.
pub(crate) fn unit_values(
    bytes: &[u8],
    error: impl FnOnce(String) -> RefineTrainError,
) -> Result<Vec<f32>, RefineTrainError> {
    let values: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    unit_range(values, error)
}

/// `values` when every one lies in [0, 1] (image values), else the error `error` makes of the first that does not.
pub(crate) fn unit_range(
    values: Vec<f32>,
    error: impl FnOnce(String) -> RefineTrainError,
) -> Result<Vec<f32>, RefineTrainError> {
    match values.iter().find(|v| !(0.0..=1.0).contains(*v)) {
        Some(bad) => Err(error(format!("value {bad} outside [0, 1]"))),
        None => Ok(values),
    }
}
