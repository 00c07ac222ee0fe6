//! The DDPM noise schedule and the refiner's single denoising step: at timestep `t` with
//! `abar = alphas_cumprod[t]`, the clean latent is `x0 = (z - sqrt(1 - abar) eps) / sqrt(abar)`.
//! A one-step DDPM schedule's previous timestep has `abar_prev = 1`, so the step returns `x0` itself (its
//! noise term has standard deviation 1e-10 and is left out).
//!
//! `alphas_cumprod` is computed as PyTorch does (`scaled_linear` betas: an f32 linspace of square roots,
//! squared; the cumulative product accumulated in f64), so it matches the reference's values bit for bit.

use std::path::Path;

use burn::tensor::Tensor;

use crate::config::{SchedulerConfig, require};
use crate::error::RefineError;

/// `prod_{s <= t} (1 - beta_s)` for every training timestep.
pub fn alphas_cumprod(config: &SchedulerConfig, path: &Path) -> Result<Vec<f32>, RefineError> {
    require(config.beta_schedule == "scaled_linear", path, || format!("beta_schedule {}", config.beta_schedule))?;
    require(config.prediction_type == "epsilon", path, || format!("prediction_type {}", config.prediction_type))?;
    require(config.num_train_timesteps >= 2, path, || "num_train_timesteps below 2".into())?;
    let roots =
        linspace_f32(config.beta_start.sqrt() as f32, config.beta_end.sqrt() as f32, config.num_train_timesteps);
    // Betas and alphas in f32, their running product accumulated in f64 (PyTorch's CPU `cumprod`).
    let mut product = 1.0f64;
    Ok(roots
        .into_iter()
        .map(|root| {
            product *= f64::from(1.0 - root * root);
            product as f32
        })
        .collect())
}

/// `steps` evenly spaced f32 values from `start` to `end`, computed as PyTorch's CPU kernel does: from the
/// start for the first half, from the end for the second.
fn linspace_f32(start: f32, end: f32, steps: usize) -> Vec<f32> {
    let step = (end - start) / (steps - 1) as f32;
    let halfway = steps / 2;
    (0..steps)
        .map(|i| if i < halfway { start + step * i as f32 } else { end - step * (steps - i - 1) as f32 })
        .collect()
}

/// The single step from a noisy latent and its noise prediction to the clean latent.
#[derive(Debug, Clone, Copy)]
pub struct SingleStep {
    pub timestep: usize,
    sqrt_alpha: f32,
    sqrt_one_minus_alpha: f32,
}

impl SingleStep {
    pub fn new(alphas_cumprod: &[f32], timestep: usize) -> Result<Self, RefineError> {
        let alpha = *alphas_cumprod.get(timestep).ok_or_else(|| {
            RefineError::Input(format!("timestep {timestep} outside the schedule's {} steps", alphas_cumprod.len()))
        })?;
        Ok(Self { timestep, sqrt_alpha: alpha.sqrt(), sqrt_one_minus_alpha: (1.0 - alpha).sqrt() })
    }

    /// `x0 = (z - sqrt(1 - abar) eps) / sqrt(abar)`.
    pub fn clean_latent(&self, noisy: Tensor<4>, eps: Tensor<4>) -> Tensor<4> {
        (noisy - eps * self.sqrt_one_minus_alpha) / self.sqrt_alpha
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sd_turbo() -> SchedulerConfig {
        SchedulerConfig {
            beta_start: 0.00085,
            beta_end: 0.012,
            beta_schedule: "scaled_linear".into(),
            num_train_timesteps: 1000,
            prediction_type: "epsilon".into(),
        }
    }

    #[test]
    fn linspace_hits_both_ends_exactly() {
        let values = linspace_f32(0.3, 0.7, 11);
        assert_eq!((values[0], values[10]), (0.3, 0.7));
        assert!(values.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn sd_turbo_schedule_at_199_matches_pytorch_bits() {
        let alphas = alphas_cumprod(&sd_turbo(), Path::new("scheduler_config.json")).unwrap();
        // alphas_cumprod[199] of PyTorch's float32 computation.
        assert_eq!(alphas[199].to_bits(), 0x3f41_5748, "{}", alphas[199]);
    }

    #[test]
    fn other_schedules_are_refused_with_the_setting_named() {
        let config = SchedulerConfig { beta_schedule: "linear".into(), ..sd_turbo() };
        let error = alphas_cumprod(&config, Path::new("s.json")).unwrap_err().to_string();
        assert!(error.contains("s.json") && error.contains("beta_schedule linear"), "{error}");
    }
}
