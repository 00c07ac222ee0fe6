//! AdamW's update of one parameter on the host in a single pass: the clipping factor, both moments, their bias
//! correction, the weight decay and the step, each new value checked for finiteness as it is written.
//!
//! Burn's AdamW runs a dozen tensor operations per parameter, each a pass over memory with an allocation of its
//! own. For a network of hundreds of small parameters on the CPU that bookkeeping, not the arithmetic, is what
//! the update costs, and it runs on the thread that drives every step. [`update`] evaluates the same `f32`
//! expressions in the same order (the rule of `burn::optim::AdamW` without AMSGrad or cautious decay), so on the
//! `Flex` device its results are those of burn's AdamW bit for bit (a test holds it to that), and it learns on
//! the way which of the new weight and moments holds a NaN or an infinity, which spares the separate check.
//!
//! The pass is written so that the compiler vectorises it (zipped slices, no indexing, no branch per value). Late
//! in a run a few percent of the second moments are subnormal, and an x86 processor takes a microcode assist for
//! each instruction that meets one: one per vector of values instead of one per value halved the update there.

use burn::optim::{AdamW, AdamWConfig};

use crate::finite::Holder;

/// The constants of AdamW's rule, as `burn::optim::AdamWConfig` keeps them (`f32`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct AdamWRule {
    pub beta_1: f32,
    pub beta_2: f32,
    pub epsilon: f32,
    pub weight_decay: f32,
}

impl AdamWRule {
    /// Burn's AdamW with these constants.
    pub fn burn_adamw(self) -> AdamW {
        AdamWConfig::new()
            .with_beta_1(self.beta_1)
            .with_beta_2(self.beta_2)
            .with_epsilon(self.epsilon)
            .with_weight_decay(self.weight_decay)
            .build()
    }
}

/// The moments of one parameter before a step, flattened, and how many steps made them.
#[derive(Clone, Copy)]
pub(crate) struct MomentsBefore<'a> {
    pub first: &'a [f32],
    pub second: &'a [f32],
    pub time: usize,
}

/// A parameter after one step: its weight, its moments and their step count, flattened.
pub(crate) struct Updated {
    pub weight: Vec<f32>,
    pub first: Vec<f32>,
    pub second: Vec<f32>,
    pub time: usize,
    /// The first of the weight, the first and the second moment (in that order) holding a non-finite value.
    pub non_finite: Option<Holder>,
}

/// One AdamW step of `weight` at learning rate `rate`, its gradient `grad` scaled by `grad_scale` first (the
/// clipping factor; burn's `mul_scalar`), from `moments` (`None`: the parameter's first step).
pub(crate) fn update(
    rule: AdamWRule,
    rate: f64,
    grad_scale: Option<f64>,
    weight: &[f32],
    grad: &[f32],
    moments: Option<MomentsBefore<'_>>,
) -> Updated {
    let count = weight.len();
    assert_eq!(grad.len(), count, "a gradient of {} values for a weight of {count}", grad.len());
    if let Some(before) = &moments {
        let sizes = [before.first.len(), before.second.len()];
        assert_eq!(sizes, [count; 2], "moments of {sizes:?} values for a weight of {count}");
    }
    let time = moments.as_ref().map_or(1, |m| m.time + 1);
    let (factor_1, factor_2) = (1.0 - rule.beta_1, 1.0 - rule.beta_2);
    // As burn computes them: the corrections in `f32` from the step count, the decay in `f64` from the rate.
    let correction_1 = 1f32 - rule.beta_1.powi(time as i32);
    let correction_2 = 1f32 - rule.beta_2.powi(time as i32);
    let decay_rate = rate * f64::from(rule.weight_decay);
    let keep = (decay_rate != 0.0).then_some((1.0 - decay_rate) as f32);
    // Without clipping or decay the factors are 1: `x · 1` is `x` to the last bit.
    let constants = StepConstants {
        beta_1: rule.beta_1,
        beta_2: rule.beta_2,
        factor_1,
        factor_2,
        correction_1,
        correction_2,
        epsilon: rule.epsilon,
        keep: keep.unwrap_or(1.0),
        rate: rate as f32,
        grad_scale: grad_scale.map_or(1.0, |s| s as f32),
    };

    let mut updated =
        Updated { weight: vec![0.0; count], first: vec![0.0; count], second: vec![0.0; count], time, non_finite: None };
    let outputs = updated.weight.iter_mut().zip(updated.first.iter_mut()).zip(updated.second.iter_mut());
    let mut finite = Finite::default();
    // Two loops over zipped slices, without indexing or branches, so that the compiler vectorises them.
    match &moments {
        Some(before) => {
            let inputs = weight.iter().zip(grad).zip(before.first).zip(before.second);
            for (((w_out, m_out), v_out), (((&w, &g), &m), &v)) in outputs.zip(inputs) {
                let g = g * constants.grad_scale;
                let m = m * constants.beta_1 + g * constants.factor_1;
                let v = v * constants.beta_2 + g * g * constants.factor_2;
                (*w_out, *m_out, *v_out) = finite.track(constants.weight(w, m, v), m, v);
            }
        }
        None => {
            for (((w_out, m_out), v_out), (&w, &g)) in outputs.zip(weight.iter().zip(grad)) {
                let g = g * constants.grad_scale;
                let (m, v) = (g * constants.factor_1, g * g * constants.factor_2);
                (*w_out, *m_out, *v_out) = finite.track(constants.weight(w, m, v), m, v);
            }
        }
    }
    let finite = [finite.weight, finite.first, finite.second];
    let holders = [Holder::Weight, Holder::FirstMoment, Holder::SecondMoment];
    updated.non_finite = finite.iter().zip(holders).find(|(finite, _)| !**finite).map(|(_, holder)| holder);
    updated
}

/// The `f32` constants of one parameter's step.
struct StepConstants {
    beta_1: f32,
    beta_2: f32,
    factor_1: f32,
    factor_2: f32,
    correction_1: f32,
    correction_2: f32,
    epsilon: f32,
    keep: f32,
    rate: f32,
    grad_scale: f32,
}

impl StepConstants {
    /// The new weight from the old one and the new moments.
    #[inline(always)]
    fn weight(&self, weight: f32, m: f32, v: f32) -> f32 {
        let delta = (m / self.correction_1) / ((v / self.correction_2).sqrt() + self.epsilon);
        weight * self.keep - delta * self.rate
    }
}

/// Whether every new weight, first and second moment so far is finite.
struct Finite {
    weight: bool,
    first: bool,
    second: bool,
}

impl Default for Finite {
    fn default() -> Self {
        Self { weight: true, first: true, second: true }
    }
}

impl Finite {
    #[inline(always)]
    fn track(&mut self, w: f32, m: f32, v: f32) -> (f32, f32, f32) {
        self.weight &= w.is_finite();
        self.first &= m.is_finite();
        self.second &= v.is_finite();
        (w, m, v)
    }
}

#[cfg(test)]
mod tests {
    use burn::optim::{AdamWState, AdaptiveMomentumState, Optimizer as _};
    use burn::tensor::{Device, Distribution, Tensor};

    use super::*;

    const RULE: AdamWRule = AdamWRule { beta_1: 0.9, beta_2: 0.999, epsilon: 1e-8, weight_decay: 1e-4 };

    fn values(tensor: &Tensor<1>) -> Vec<f32> {
        tensor.clone().into_data().try_to_vec::<f32>().expect("f32 values")
    }

    /// Burn's AdamW on the `Flex` device and [`update`] over five steps, with and without clipping and decay.
    fn against_burn(rule: AdamWRule, grad_scale: Option<f64>) {
        let device = Device::flex();
        let adamw = rule.burn_adamw();
        let count = 1000;
        let mut weight = Tensor::<1>::random([count], Distribution::Normal(0.0, 1.0), &device);
        let mut host_weight = values(&weight);
        let mut state: Option<AdamWState<1>> = None;
        let mut host: Option<(Vec<f32>, Vec<f32>, usize)> = None;
        for step in 0..5 {
            let grad = Tensor::<1>::random([count], Distribution::Normal(0.0, 0.1 * (step + 1) as f64), &device);
            let rate = 6e-3 / (step + 1) as f64;
            let host_grad = values(&grad);
            let scaled = grad_scale.map_or(grad.clone(), |s| grad.mul_scalar(s));
            let (next, next_state) = adamw.step(rate, weight, scaled, state);
            let moments = host.as_ref().map(|(first, second, time)| MomentsBefore { first, second, time: *time });
            let updated = update(rule, rate, grad_scale, &host_weight, &host_grad, moments);
            let AdaptiveMomentumState { time, moment_1, moment_2, .. } =
                next_state.clone().expect("a state after a step").momentum;
            assert_eq!(updated.weight, values(&next), "weights after step {step}");
            assert_eq!((updated.first.clone(), updated.second.clone()), (values(&moment_1), values(&moment_2)));
            assert_eq!(updated.time, time, "step count");
            assert_eq!(updated.non_finite, None, "finite values are not reported");
            (weight, state, host_weight) = (next, next_state, updated.weight);
            host = Some((updated.first, updated.second, updated.time));
        }
    }

    #[test]
    fn the_update_is_burns_adamw_bit_for_bit() {
        against_burn(RULE, None);
        against_burn(RULE, Some(0.37));
        against_burn(AdamWRule { weight_decay: 0.0, ..RULE }, Some(0.5));
    }

    #[test]
    fn the_first_non_finite_holder_is_named() {
        let before = MomentsBefore { first: &[0.0, 0.0], second: &[0.0, f32::INFINITY], time: 3 };
        let updated = update(RULE, 1e-3, None, &[1.0, 2.0], &[0.5, 0.5], Some(before));
        assert_eq!(updated.non_finite, Some(Holder::SecondMoment), "only the second moment overflowed");
        let updated = update(RULE, 1e-3, None, &[1.0, f32::NAN], &[0.5, 0.5], None);
        assert_eq!(updated.non_finite, Some(Holder::Weight), "the weight comes first");
        let updated = update(RULE, 1e-3, None, &[1.0, 2.0], &[f32::MAX, 0.5], None);
        assert_eq!(updated.non_finite, Some(Holder::SecondMoment), "g² overflows, m does not");
        let updated = update(RULE, 1e-3, Some(1e30), &[1.0, 2.0], &[1e10, 0.5], None);
        assert_eq!(updated.non_finite, Some(Holder::Weight), "an overflowing gradient leaves ∞ / ∞ in the weight");
    }
}
