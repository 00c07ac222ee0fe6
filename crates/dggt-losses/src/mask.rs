//! Binary cross-entropy losses on masks (`[V, H, W]` at the project's API; any shape works).
//!
//! * [`bce_probabilities`]: BCE of probabilities against targets in [0, 1]. The project uses it as the
//!   opacity loss ([`opacity_loss`]): the rendered alpha against `1 - sky mask`. The probability is clamped
//!   to `[PROBABILITY_EPS, 1 - PROBABILITY_EPS]` for the logarithms, but the clamp is straight-through: the
//!   gradient is that of the BCE at the clamped value (`(p - y) / (p (1 - p))` there), so an alpha of exactly
//!   0 or 1 gives a finite loss and a finite, non-zero gradient that still pulls it towards the target
//!   (a plain clamp would give a zero gradient there).
//! * [`bce_with_logits`]: BCE from logits (dynamic logits against the dynamic mask) in the overflow-free form
//!   `max(x, 0) - x y + ln(1 + exp(-|x|))`, with `max(x, 0)` written as `(x + |x|) / 2` so that the autodiff
//!   gradient is `sigmoid(x) - y` everywhere, `x = 0` included.
//!
//! Both return the mean over all elements as a one-element tensor.

use burn::tensor::Tensor;

use crate::error::LossError;
use crate::images::check_same;

/// Probabilities are clamped to `[PROBABILITY_EPS, 1 - PROBABILITY_EPS]` inside the logarithms.
pub const PROBABILITY_EPS: f32 = 1e-6;

/// Mean BCE `-(y ln p + (1 - y) ln(1 - p))` of probabilities `p` against targets `y`, with the
/// straight-through clamp described in the module docs.
pub fn bce_probabilities<const D: usize>(probabilities: Tensor<D>, targets: Tensor<D>) -> Result<Tensor<1>, LossError> {
    check_same("bce_probabilities", &probabilities, &targets)?;
    let p = probabilities.clone().clamp(PROBABILITY_EPS, 1.0 - PROBABILITY_EPS);
    // Value of the clamp, gradient of the identity.
    let p = probabilities.clone() + (p - probabilities).detach();
    let positive = targets.clone() * p.clone().log();
    let negative = targets.neg().add_scalar(1.0) * p.neg().add_scalar(1.0).log();
    Ok((positive + negative).neg().mean())
}

/// The opacity loss: mean BCE of the rendered `alpha` against `1 - sky_mask` (sky pixels should stay
/// transparent, all others opaque). Both `[V, H, W]` (or any equal shapes), values in [0, 1].
pub fn opacity_loss(alpha: Tensor<3>, sky_mask: Tensor<3>) -> Result<Tensor<1>, LossError> {
    check_same("opacity_loss", &alpha, &sky_mask)?;
    bce_probabilities(alpha, sky_mask.neg().add_scalar(1.0))
}

/// Mean BCE of `sigmoid(logits)` against targets `y` in [0, 1], computed from the logits without overflow:
/// `max(x, 0) - x y + ln(1 + exp(-|x|))`.
pub fn bce_with_logits<const D: usize>(logits: Tensor<D>, targets: Tensor<D>) -> Result<Tensor<1>, LossError> {
    check_same("bce_with_logits", &logits, &targets)?;
    let magnitude = logits.clone().abs();
    let positive_part = (logits.clone() + magnitude.clone()).mul_scalar(0.5);
    let softplus_tail = magnitude.neg().exp().log1p();
    Ok((positive_part - logits * targets + softplus_tail).mean())
}
