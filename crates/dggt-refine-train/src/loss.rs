//! The refiner's training loss, as Difix's: `l2 · L2 + lpips · LPIPS + gram · Gram`, on refined images and
//! their targets `[N, 3, H, W]` in [0, 1].
//!
//! L2 is the mean squared error of the images in [-1, 1] (where the refiner's decoder works), LPIPS the
//! evaluation form (images mapped to [-1, 1]), the Gram loss on the VGG-16 taps of the [0, 1] images with
//! ImageNet normalisation (`dggt_losses::gram`). Each term is averaged over the batch. The Gram term may start
//! late (`loss.gram_start_step`, as the Difix release's `gram_loss_warmup_steps`): before that step it is
//! neither computed nor added, and its recorded value is 0.

use burn::tensor::{Device, Tensor};
use dggt_losses::{GramLoss, Lpips, l2};

use crate::config::LossSection;
use crate::error::RefineTrainError;

/// The weighted loss and its terms' values.
pub struct LossValue {
    pub total: Tensor<1>,
    pub l2: f64,
    pub lpips: f64,
    pub gram: f64,
}

pub struct RefineLoss {
    lpips: Lpips,
    gram: GramLoss,
    weights: [f64; 3],
    gram_start_step: u64,
}

impl RefineLoss {
    pub fn load(section: &LossSection, device: &Device) -> Result<Self, RefineTrainError> {
        let lpips = Lpips::load(section.lpips_kind, &section.lpips_weights, &section.lpips_weights, device)?;
        let gram = GramLoss::load(&section.gram_vgg, device)?;
        let weights = [section.l2, section.lpips, section.gram];
        Ok(Self { lpips, gram, weights, gram_start_step: section.gram_start_step })
    }

    /// The loss of `refined` against `target` at optimiser step `step` (which decides whether the Gram term
    /// counts yet).
    pub fn compute(&self, refined: Tensor<4>, target: Tensor<4>, step: u64) -> Result<LossValue, RefineTrainError> {
        let l2_term = l2(refined.clone() * 2.0, target.clone() * 2.0)?;
        let (refined, target) = (refined.permute([0, 2, 3, 1]), target.permute([0, 2, 3, 1]));
        let lpips_term = self.lpips.eval(refined.clone(), target.clone())?.mean();
        let scalar = |t: &Tensor<1>| -> f64 {
            let value: f32 = t.clone().into_scalar();
            value.into()
        };
        let (l2, lpips) = (scalar(&l2_term), scalar(&lpips_term));
        let [w_l2, w_lpips, w_gram] = self.weights;
        let total = l2_term * w_l2 + lpips_term * w_lpips;
        if step < self.gram_start_step {
            return Ok(LossValue { total, l2, lpips, gram: 0.0 });
        }
        let gram_term = self.gram.forward(refined, target)?.value.mean();
        let gram = scalar(&gram_term);
        Ok(LossValue { total: total + gram_term * w_gram, l2, lpips, gram })
    }
}
