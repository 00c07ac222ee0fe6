//! Parity of the DGGT network with the release: the network a vector folder's `config.json` describes is
//! built, loaded and run on its inputs, and every reference output is reproduced by name ([`outputs`]) and
//! compared with the port's ([`comparison`]).
//!
//! Tolerance: [`crate::tolerance::NETWORK`] on the largest absolute difference. Two outputs are compared on a
//! well-conditioned part: `gs_conf = 1 / (relu(x) + 1e-6)` through its reciprocal (a 1e-6 error in `x` near 0 is
//! a huge error in `gs_conf`), and sky pixel locations only where the point is seen (in front of the camera and
//! inside the image: behind it the release's values are clamped garbage, at grazing depths `x / z` amplifies the
//! reference's `f32` rounding).
//!
//! Rendered images (`render.fg_*`, `render.sky_*`, `render.final_rgb`) are compared pixel by pixel: they pass
//! when at least [`RENDER_PIXEL_FRACTION`] of the pixels are within tolerance on every channel. Rasterisers
//! differ in accumulation order, so a pixel whose transmittance crosses the 1e-4 stop, or a Gaussian whose alpha
//! crosses 1/255, on one side only can legitimately differ; the row's note gives the fraction.

mod comparison;
mod outputs;
mod prediction;
pub mod release_render;
pub mod reproduce_error;

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_model::Dggt;
use dggt_model::weights::LoadReport;

pub use comparison::RENDER_PIXEL_FRACTION;

use crate::error::ParityError;
use crate::report::{ParityReport, ParityRow, Status};
use crate::vectors::{HostTensor, ParityVectors};
use prediction::Prediction;

/// One run of the network's vectors: the weights loaded, what loading consumed, and the comparison.
#[derive(Debug, Clone)]
pub struct NetworkRun {
    pub weights: PathBuf,
    pub load: LoadReport,
    pub report: ParityReport,
}

/// Builds the network of `vectors`, loads `weights`, runs it on the vectors' images on `device` and compares
/// every reference output.
pub fn run_parity(vectors: &ParityVectors, weights: &Path, device: &Device) -> Result<NetworkRun, ParityError> {
    let (model, load) = Dggt::from_checkpoint(&vectors.config, weights, device)?;
    let images = vectors.images(device)?;
    let out = model.forward(images.clone())?;
    let mut prediction = Prediction::new(&model, images, out);
    prediction.sky_mask = vectors.input("sky_mask").cloned();
    let rows = vectors.outputs.iter().map(|(name, reference)| reproduce(&prediction, name, reference)).collect();
    Ok(NetworkRun { weights: weights.to_path_buf(), load, report: ParityReport { rows } })
}

/// The row of reference output `name`: reproduced by its rule and compared, or why it was not compared.
fn reproduce(prediction: &Prediction, name: &str, reference: &HostTensor) -> ParityRow {
    let Some((reproduce, key)) = outputs::lookup(name) else {
        return ParityRow::not_compared(name, &reference.shape, Status::Unknown);
    };
    match reproduce(prediction, &key) {
        Ok(actual) => comparison::compare(name, &actual, reference),
        Err(reason) => ParityRow::not_compared(name, &reference.shape, Status::NotProduced(reason.to_string())),
    }
}
