//! The optimiser around burn's AdamW: parameter groups with their own learning rates, global gradient-norm
//! clipping, and a step that never leaves a non-finite value behind.
//!
//! Groups are sets of parameters the trainer names (the DGGT trainer: the network's top-level modules,
//! `sky_model`, `gs_head`, ...), each with its own peak rate. Every group shares one AdamW state
//! map (keyed by parameter id, so it survives checkpoints) and is stepped with its own rate; clipping scales all
//! gradients together so that their joint L2 norm is at most the limit. The state is saved and loaded tensor by
//! tensor, so a checkpoint of a 1.3B-parameter run never holds a second copy of its 10 GB of moments.
//!
//! A step never leaves a non-finite value behind: one whose gradient norm is not finite is not applied, and
//! one whose update makes a weight or moment non-finite is rolled back ([`StepOutcome`]). The rollback keeps
//! the previous weights and moments alive until the updated ones are checked, so the update's peak memory holds
//! both (burn's tensors are shared, not copied, so nothing else is spent on it). A host pass checks each value
//! as it writes it; where any parameter was stepped by burn's AdamW, the whole model and its moments are checked
//! after the update ([`first_non_finite`]). Weights and moments a step leaves as they were are not checked again.

use std::collections::HashMap;
use std::path::Path;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::optim::{AdamW, AdamWState, AdaptiveMomentumState, GradientsParams, Optimizer as _};
use burn::tensor::{DType, Device, Tensor, TensorData};
use dggt_checkpoint::deferred_tensor;

use crate::error::RunError;
use crate::finite::{Holder, Moments, NonFinite, first_non_finite};
use crate::host_adamw::{self, AdamWRule, MomentsBefore};
use crate::optim_config::OptimSection;

/// AdamW with groups and clipping.
///
/// The update of each parameter is burn's [`AdamW`] rule, applied to the flattened parameter (the update is
/// elementwise, so flattening changes nothing): in one host pass for `f32` parameters on the `Flex` device, which
/// also checks what it writes for finiteness, and through burn's own AdamW everywhere else. The moments live
/// here, keyed by parameter id, so that a checkpoint can write them one tensor at a time ([`Optimizer::save`]).
pub struct Optimizer {
    adamw: AdamW,
    /// The constants `adamw` was built with, for the host pass.
    rule: AdamWRule,
    /// Flattened moments and step count of every parameter stepped so far.
    states: HashMap<ParamId, AdamWState<1>>,
    /// Peak rate of everything outside the groups.
    base_rate: f64,
    /// Peak rate of every parameter of a group.
    group_rates: HashMap<ParamId, f64>,
    clip_norm: Option<f64>,
}

/// What an applied optimiser step measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// Global gradient norm before clipping.
    pub grad_norm: f64,
    /// Whether the gradients were scaled down.
    pub clipped: bool,
}

/// What one optimiser step did.
#[derive(Debug, Clone, PartialEq)]
pub enum StepOutcome {
    /// The update was applied.
    Applied(StepReport),
    /// The gradient norm was not finite: nothing was updated.
    NonFiniteGradient,
    /// The update made a weight or moment non-finite (the first one found is named): the weights and moments
    /// are those from before the step.
    RolledBack { report: StepReport, non_finite: NonFinite },
}

impl StepOutcome {
    /// The report of a step that computed an update (applied or rolled back).
    pub fn report(&self) -> Option<StepReport> {
        match self {
            Self::Applied(report) | Self::RolledBack { report, .. } => Some(*report),
            Self::NonFiniteGradient => None,
        }
    }
}

impl Optimizer {
    /// The optimiser whose parameters in `group_rates` take their own peak rate, every other one
    /// `config.lr`.
    pub fn grouped(config: &OptimSection, group_rates: HashMap<ParamId, f64>) -> Self {
        Self { group_rates, ..Self::ungrouped(config) }
    }

    /// The optimiser of any module, every parameter at `config.lr` (`config.groups` and `config.frozen` name
    /// a network's modules and are not consulted).
    pub fn ungrouped(config: &OptimSection) -> Self {
        let rule = AdamWRule {
            beta_1: config.beta1 as f32,
            beta_2: config.beta2 as f32,
            epsilon: config.epsilon as f32,
            weight_decay: config.weight_decay as f32,
        };
        Self {
            adamw: rule.burn_adamw(),
            rule,
            states: HashMap::new(),
            base_rate: config.lr,
            group_rates: HashMap::new(),
            clip_norm: config.clip_grad_norm,
        }
    }

    /// Global L2 norm of `grads` over `model`'s parameters.
    pub fn grad_norm<M: Module>(model: &M, grads: &GradientsParams) -> f64 {
        let mut norm = SquaredNorm { grads, sum: 0.0 };
        model.visit(&mut norm);
        norm.sum.sqrt()
    }

    /// Applies one step at schedule factor `factor` (the fraction of each peak rate) and returns the model
    /// after it: the updated one, or `model` itself when the gradient norm is not finite or the update made a
    /// weight or moment non-finite (then the moments are restored too). Parameters of a group whose rate is
    /// zero are not stepped.
    pub fn step<M: Module>(&mut self, model: M, mut grads: GradientsParams, factor: f64) -> (M, StepOutcome) {
        let grad_norm = Self::grad_norm(&model, &grads);
        if !grad_norm.is_finite() {
            return (model, StepOutcome::NonFiniteGradient);
        }
        let grad_scale = self.clip_norm.filter(|&limit| grad_norm > limit).map(|limit| limit / grad_norm);
        let report = StepReport { grad_norm, clipped: grad_scale.is_some() };
        let (model_before, states_before) = (model.clone(), self.states.clone());
        let mut update = Update {
            optimizer: self,
            grads: &mut grads,
            factor,
            grad_scale,
            path: Vec::new(),
            check: Default::default(),
        };
        let updated = model.map(&mut update);
        let non_finite = match update.check {
            UpdateCheck::Complete => None,
            UpdateCheck::CompleteWith(non_finite) => Some(non_finite),
            UpdateCheck::Partial => first_non_finite(&updated, Some(&*self)),
        };
        match non_finite {
            None => (updated, StepOutcome::Applied(report)),
            Some(non_finite) => {
                self.states = states_before;
                (model_before, StepOutcome::RolledBack { report, non_finite })
            }
        }
    }

    /// A copy of this optimiser, its state moved to `device` (for the replica there).
    pub fn fork(&self, device: &Device) -> Self {
        Self {
            adamw: self.adamw.clone(),
            rule: self.rule,
            states: self.states.iter().map(|(id, state)| (*id, AdamW::to_device(state.clone(), device))).collect(),
            base_rate: self.base_rate,
            group_rates: self.group_rates.clone(),
            clip_norm: self.clip_norm,
        }
    }

    /// The peak rate of parameter `id`.
    fn rate(&self, id: &ParamId) -> f64 {
        self.group_rates.get(id).copied().unwrap_or(self.base_rate)
    }

    /// Writes the moments to a burnpack file, one tensor at a time (each read back from its device only when
    /// the writer reaches it), atomically.
    pub fn save(&self, path: &Path) -> Result<(), RunError> {
        let mut tensors = Vec::with_capacity(2 * self.states.len());
        let mut steps = Vec::with_capacity(self.states.len());
        let mut ids: Vec<&ParamId> = self.states.keys().collect();
        ids.sort_by_key(|id| id.val());
        for id in ids {
            let moments = &self.states[id].momentum;
            tensors.push(deferred_tensor(format!("{}.{MOMENT_1}", id.val()), &moments.moment_1, id));
            tensors.push(deferred_tensor(format!("{}.{MOMENT_2}", id.val()), &moments.moment_2, id));
            steps.push((format!("{}.{STEPS}", id.val()), moments.time));
        }
        let writer = steps
            .into_iter()
            .fold(burn_pack::Writer::new(tensors), |writer, (key, time)| writer.with_scalar(&key, time.into()));
        writer.write_to_file(path).map_err(|e| optimizer_file_error(path, e))
    }

    /// Replaces the moments with those saved at `path`, on `device`.
    pub fn load(&mut self, path: &Path, device: &Device) -> Result<(), RunError> {
        let reader = burn_pack::Reader::from_file(path).map_err(|e| optimizer_file_error(path, e))?;
        let steps = reader.scalars().clone();
        let mut moments: HashMap<u64, [Option<Tensor<1>>; 2]> = HashMap::new();
        for tensor in reader.into_tensors().map_err(|e| optimizer_file_error(path, e))? {
            let (name, dtype, shape, id, bytes) = tensor.into_parts().map_err(|e| optimizer_file_error(path, e))?;
            let (Some(id), [n]) = (id, shape.as_slice()) else {
                return Err(optimizer_file_error(
                    path,
                    format!("`{name}`: expected a flat moment with a parameter id"),
                ));
            };
            let slot = match name.rsplit('.').next() {
                Some(MOMENT_1) => 0,
                Some(MOMENT_2) => 1,
                _ => return Err(optimizer_file_error(path, format!("unexpected tensor `{name}`"))),
            };
            let data = TensorData::from_bytes(bytes, [*n], dtype);
            moments.entry(id).or_default()[slot] = Some(Tensor::from_data(data, device));
        }
        self.states.clear();
        for (id, [first, second]) in moments {
            let key = format!("{id}.{STEPS}");
            let time = steps.get(&key).and_then(|s| usize::try_from(*s).ok());
            let (Some(moment_1), Some(moment_2), Some(time)) = (first, second, time) else {
                return Err(optimizer_file_error(path, format!("parameter {id}: both moments and `{key}` expected")));
            };
            let momentum = AdaptiveMomentumState { time, moment_1, moment_2, max_moment_2: None };
            self.states.insert(ParamId::from(id), AdamWState { momentum });
        }
        Ok(())
    }

    /// Gives every parameter of `model` that takes gradients zero moments at step count 0, the state a first
    /// step starts from: a full-size state without running a step (the checkpoint benchmark).
    pub fn zero_moments<M: Module>(&mut self, model: &M) {
        struct Zero<'a>(&'a mut HashMap<ParamId, AdamWState<1>>);
        impl ModuleVisitor for Zero<'_> {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                let value = param.val();
                if value.is_require_grad() {
                    let zeros = || Tensor::<1>::zeros([value.shape().num_elements()], &value.device());
                    let momentum =
                        AdaptiveMomentumState { time: 0, moment_1: zeros(), moment_2: zeros(), max_moment_2: None };
                    self.0.insert(param.id, AdamWState { momentum });
                }
            }
        }
        model.visit(&mut Zero(&mut self.states));
    }
}

impl Moments for Optimizer {
    fn moments(&self, id: &ParamId) -> Option<[&Tensor<1>; 2]> {
        self.states.get(id).map(|state| [&state.momentum.moment_1, &state.momentum.moment_2])
    }
}

/// Names of the saved state of one parameter: `{id}.moment_1`, `{id}.moment_2` and the scalar `{id}.steps`.
const MOMENT_1: &str = "moment_1";
const MOMENT_2: &str = "moment_2";
const STEPS: &str = "steps";

// Takes any error by value, like `impl Into<String>`, so `map_err(|e| ..(path, e))` reads plainly.
#[allow(clippy::needless_pass_by_value)]
fn optimizer_file_error(path: &Path, detail: impl ToString) -> RunError {
    RunError::Checkpoint { path: path.to_path_buf(), detail: detail.to_string() }
}

/// Steps every parameter that has a gradient, keeping its autodiff association: `f32` parameters on the `Flex`
/// device in one host pass each ([`host_adamw`]), every other one through burn's AdamW.
struct Update<'a> {
    optimizer: &'a mut Optimizer,
    grads: &'a mut GradientsParams,
    factor: f64,
    /// The clipping factor the gradients are scaled by, if any.
    grad_scale: Option<f64>,
    /// The module path of the parameter being visited.
    path: Vec<String>,
    check: UpdateCheck,
}

/// What the host passes of an [`Update`] learnt about the finiteness of what it changed.
#[derive(Debug, Default)]
enum UpdateCheck {
    /// Every changed weight and moment was checked on the way; the first non-finite one, if any.
    #[default]
    Complete,
    CompleteWith(NonFinite),
    /// Some parameter was stepped by burn's AdamW: the whole model is to be checked.
    Partial,
}

impl UpdateCheck {
    fn record(&mut self, parameter: &[String], holder: Option<Holder>) {
        if let (Self::Complete, Some(holder)) = (&*self, holder) {
            *self = Self::CompleteWith(NonFinite { parameter: parameter.join("."), holder });
        }
    }
}

impl Update<'_> {
    /// `flat` stepped in one host pass, when it, its gradient and its moments (of its size) are `f32` on the
    /// `Flex` device; otherwise `None`, nothing changed.
    fn host_step(&mut self, id: ParamId, rate: f64, flat: &Tensor<1>, grad: &Tensor<1>) -> Option<Tensor<1>> {
        let state = self.optimizer.states.get(&id);
        let moments = state.map(|s| [&s.momentum.moment_1, &s.momentum.moment_2]);
        let tensors = [flat, grad].into_iter().chain(moments.into_iter().flatten());
        if !tensors.into_iter().all(|t| t.dtype() == DType::F32 && on_flex(t)) {
            return None;
        }
        let read = |t: &Tensor<1>| t.clone().into_data().try_into_vec::<f32>().ok();
        let (weight, grad) = (read(flat)?, read(grad)?);
        let before = match moments {
            Some([first, second]) => Some((read(first)?, read(second)?, state.map_or(0, |s| s.momentum.time))),
            None => None,
        };
        if before.as_ref().is_some_and(|(first, second, _)| first.len() != weight.len() || second.len() != weight.len())
        {
            return None;
        }
        let moments = before.as_ref().map(|(first, second, time)| MomentsBefore { first, second, time: *time });
        let updated = host_adamw::update(self.optimizer.rule, rate, self.grad_scale, &weight, &grad, moments);
        self.check.record(&self.path, updated.non_finite);
        let device = flat.device();
        let tensor = |values: Vec<f32>| Tensor::<1>::from_data(TensorData::new(values, [weight.len()]), &device);
        let momentum = AdaptiveMomentumState {
            time: updated.time,
            moment_1: tensor(updated.first),
            moment_2: tensor(updated.second),
            max_moment_2: None,
        };
        self.optimizer.states.insert(id, AdamWState { momentum });
        Some(tensor(updated.weight))
    }

    /// `flat` stepped by burn's AdamW (its gradient scaled first).
    fn burn_step(&mut self, id: ParamId, rate: f64, flat: Tensor<1>, grad: Tensor<1>) -> Tensor<1> {
        self.check = UpdateCheck::Partial;
        let device = flat.device();
        let grad = match self.grad_scale {
            Some(scale) => grad.mul_scalar(scale),
            None => grad,
        };
        let state = self.optimizer.states.remove(&id).map(|s| AdamW::to_device(s, &device));
        let (updated, state) = self.optimizer.adamw.step(rate, flat, grad, state);
        if let Some(state) = state {
            self.optimizer.states.insert(id, state);
        }
        updated
    }
}

impl ModuleMapper for Update<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let (id, tensor, mapper) = param.consume();
        let rate = self.optimizer.rate(&id) * self.factor;
        let Some(grad) = self.grads.remove::<D>(id).filter(|_| rate > 0.0) else {
            return Param::from_mapped_value(id, tensor, mapper);
        };
        let (dims, require_grad) = (tensor.dims(), tensor.is_require_grad());
        let strategy = tensor.gradient_checkpointing_strategy();
        let flat = tensor.inner().reshape([dims.iter().product::<usize>()]);
        let grad = grad.inner().to_device(&flat.device()).reshape([flat.dims()[0]]);
        let updated = match self.host_step(id, rate, &flat, &grad) {
            Some(updated) => updated,
            None => self.burn_step(id, rate, flat, grad),
        };
        let mut updated = updated.reshape(dims).autodiff();
        if let Some(strategy) = strategy {
            updated = updated.with_gradient_checkpointing_strategy(strategy);
        }
        if require_grad {
            updated = updated.require_grad();
        }
        Param::from_mapped_value(id, updated, mapper)
    }
}

fn on_flex(tensor: &Tensor<1>) -> bool {
    tensor.device().without_autodiff() == Device::flex()
}

struct SquaredNorm<'a> {
    grads: &'a GradientsParams,
    sum: f64,
}

impl ModuleVisitor for SquaredNorm<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(grad) = self.grads.get::<D>(param.id) {
            self.sum += squared_sum(grad);
        }
    }
}

/// Tensors of this many elements or more are summed by rows in [`squared_sum`].
const SUM_BY_ROWS_FROM: usize = 1 << 20;
/// Elements summed on the device per row of [`squared_sum`].
const SUM_ROW: usize = 4096;

/// `Σ x²` over `tensor`, in the same order on every run. A plain `sum()` is one reduction in a fixed order
/// on the CPU backends up to a few million elements, but from four million on the default backend sums
/// parallel pieces whose grouping follows the thread scheduling, so the norm of a large gradient — and the
/// clipping it decides — could differ in its last bits between a resumed run and an uninterrupted one. Tensors
/// of [`SUM_BY_ROWS_FROM`] elements or more are therefore summed in rows of [`SUM_ROW`] on the device (one
/// reduction per row), and the row sums read back and added in order in f64. (On a GPU, other kernels
/// accumulate with atomics, so runs there agree to rounding rather than bit for bit anyway.)
fn squared_sum<const D: usize>(tensor: Tensor<D>) -> f64 {
    let count = tensor.shape().num_elements();
    let squares = tensor.powi_scalar(2);
    if count < SUM_BY_ROWS_FROM {
        let sum: f32 = squares.sum().into_scalar();
        return sum.into();
    }
    let squares = squares.reshape([count]);
    let rows = count / SUM_ROW;
    let mut partial =
        vec![squares.clone().slice(0..rows * SUM_ROW).reshape([rows, SUM_ROW]).sum_dim(1).reshape([rows])];
    if count > rows * SUM_ROW {
        partial.push(squares.slice(rows * SUM_ROW..count).sum());
    }
    let sums = Tensor::cat(partial, 0).into_data().convert::<f64>();
    sums.iter::<f64>().sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;

    #[test]
    fn a_large_squared_sum_is_the_same_every_time_and_accurate() {
        let device = Device::flex();
        // Above the size the CPU backend sums in scheduling-dependent pieces, with a tail shorter than a row.
        let count = 2000 * SUM_ROW + 123;
        let tensor = Tensor::<1>::random([count], Distribution::Normal(0.0, 1.0), &device);
        let values = tensor.clone().into_data().convert::<f64>();
        let exact: f64 = values.iter::<f64>().map(|v| v * v).sum();
        let sums: std::collections::BTreeSet<u64> = (0..100).map(|_| squared_sum(tensor.clone()).to_bits()).collect();
        assert_eq!(sums.len(), 1, "one value over 100 sums of the same tensor");
        let sum = f64::from_bits(*sums.first().unwrap());
        assert!((sum - exact).abs() <= 1e-6 * exact, "{sum} against {exact}");
        assert_eq!(squared_sum(Tensor::<2>::zeros([0, 3], &device)), 0.0);
        assert_eq!(squared_sum(Tensor::<1>::ones([SUM_BY_ROWS_FROM + 1], &device)), (SUM_BY_ROWS_FROM + 1) as f64);
        assert_eq!(squared_sum(Tensor::<2>::from_data([[3.0f32, 4.0]], &device)), 25.0);
    }
}
