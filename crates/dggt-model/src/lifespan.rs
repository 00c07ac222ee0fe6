//! Time in a DGGT scene: the frame timestamps, the split of each pixel Gaussian's opacity into a static and a
//! dynamic part, and the lifespan decay that fades a static Gaussian away from the time of the frame it was
//! predicted in.
//!
//! The functions are tensor expressions, differentiable on an autodiff device, so that training can use them
//! as they are. They follow the release's formulas, including its numeric quirks.

use burn::tensor::Tensor;
use burn::tensor::activation::sigmoid;

/// Added to `gamma²` in the decay's denominator.
const LIFESPAN_EPS: f32 = 1e-6;

/// The release's time of each of `frames` frames: `t_i = i / (S - 1) * (S / 4)`, so the span grows with the
/// clip length (0 for a single frame).
pub fn frame_times(frames: usize) -> Vec<f64> {
    let span = frames as f64 / 4.0;
    (0..frames).map(|i| if frames > 1 { i as f64 / (frames - 1) as f64 * span } else { 0.0 }).collect()
}

/// Static opacity `o · (1 - sigmoid(logit))` from the opacity `o` and the dynamic logit.
pub fn static_opacity<const D: usize>(opacity: Tensor<D>, dynamic_logit: Tensor<D>) -> Tensor<D> {
    opacity * sigmoid(dynamic_logit).neg().add_scalar(1.0)
}

/// Dynamic opacity `o · sigmoid(logit)`: a frame's dynamic Gaussians, rendered at that frame only, undecayed.
pub fn dynamic_opacity<const D: usize>(opacity: Tensor<D>, dynamic_logit: Tensor<D>) -> Tensor<D> {
    opacity * sigmoid(dynamic_logit)
}

/// Opacity `alpha` of Gaussians predicted at times `source_times` (any shape matching `alpha`), seen at time
/// `time`: `alpha · exp(ln(0.1) / (gamma² + 1e-6) · (time - t)²)`, where `gamma` is the lifespan (`gs_conf`).
/// At `|time - t| = gamma` a Gaussian keeps a tenth of its opacity.
pub fn opacity_at<const D: usize>(
    alpha: Tensor<D>,
    lifespan: Tensor<D>,
    source_times: Tensor<D>,
    time: f64,
) -> Tensor<D> {
    // The release takes ln(0.1) and the denominator in f32 and the rest in f64 (its timestamps are f64), then
    // casts back; in f32 throughout the result differs by a few ulps.
    let rate = lifespan.powi_scalar(2).add_scalar(LIFESPAN_EPS).recip().mul_scalar(0.1f32.ln());
    let offset = source_times.sub_scalar(time as f32);
    alpha * (rate * offset.clone() * offset).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    fn tensor(values: &[f32]) -> Tensor<1> {
        Tensor::from_data(TensorData::new(values.to_vec(), [values.len()]), &Device::flex())
    }

    fn values(tensor: Tensor<1>) -> Vec<f32> {
        tensor.into_data().try_into_vec::<f32>().unwrap()
    }

    #[test]
    fn frame_times_follow_the_release() {
        assert_eq!(frame_times(3), [0.0, 0.375, 0.75]);
        assert_eq!(frame_times(1), [0.0]);
    }

    #[test]
    fn opacity_splits_and_decays() {
        let (o, logit) = (tensor(&[0.5, 0.8]), tensor(&[0.0, 2.0]));
        let split: Vec<f32> = values(static_opacity(o.clone(), logit.clone()))
            .iter()
            .zip(values(dynamic_opacity(o, logit)))
            .map(|(s, d)| s + d)
            .collect();
        assert!((split[0] - 0.5).abs() < 1e-6 && (split[1] - 0.8).abs() < 1e-6, "{split:?}");
        // One lifespan away: a tenth; at the source time: unchanged.
        let decayed = values(opacity_at(tensor(&[1.0, 1.0]), tensor(&[0.5, 0.5]), tensor(&[0.0, 0.5]), 0.5));
        assert!((decayed[0] - 0.1).abs() < 1e-5 && decayed[1] == 1.0, "{decayed:?}");
    }
}
