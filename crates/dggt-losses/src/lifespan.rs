//! The lifespan regulariser: `mean(1 / |sigma|)` over the lifespans `sigma` of the static Gaussians (an L1
//! penalty on the inverse lifespan, which pushes static Gaussians towards long lifespans).
//!
//! `|sigma|` is clamped from below at [`MIN_LIFESPAN`] with a straight-through clamp (the gradient is that of
//! `1 / |sigma|` at the clamped value), so a lifespan of 0 or below 1e-6 gives a finite loss (at most 1e6 per
//! Gaussian) and a finite gradient; huge lifespans (1e6 and beyond) give values and gradients near 0, as they
//! should.

use burn::tensor::Tensor;

use crate::error::LossError;

/// Lifespans are clamped from below at this value.
pub const MIN_LIFESPAN: f32 = 1e-6;

/// `mean(1 / max(|sigma|, MIN_LIFESPAN))` over a non-empty `[N]` tensor of lifespans.
pub fn lifespan_l1(lifespans: Tensor<1>) -> Result<Tensor<1>, LossError> {
    if lifespans.dims()[0] == 0 {
        return Err(LossError::InvalidInput("lifespan_l1: no lifespans".into()));
    }
    let magnitude = lifespans.abs();
    let clamped = magnitude.clone().clamp_min(MIN_LIFESPAN);
    let magnitude = magnitude.clone() + (clamped - magnitude).detach();
    Ok(magnitude.recip().mean())
}
