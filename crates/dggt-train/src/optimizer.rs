//! The optimiser around burn's AdamW: frozen modules, parameter groups with their own learning rates, global
//! gradient-norm clipping and gradient accumulation.
//!
//! Groups are the network's top-level modules (`sky_model`, `gs_head`, ...). Every group shares one AdamW state
//! map (keyed by parameter id, so it survives checkpoints) and is stepped with its own rate; clipping scales all
//! gradients together so that their joint L2 norm is at most the limit.

use std::collections::BTreeMap;

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::Tensor;
use dggt_model::Dggt;

use crate::config::OptimSection;
use crate::error::TrainError;

/// Freezes the named top-level modules: their parameters get no gradient and are never updated.
pub fn freeze(mut model: Dggt, names: &[String]) -> Result<Dggt, TrainError> {
    for name in names {
        match name.as_str() {
            "aggregator" => model.aggregator = model.aggregator.no_grad(),
            "camera_head" => model.camera_head = model.camera_head.no_grad(),
            "depth_head" => model.depth_head = model.depth_head.no_grad(),
            "point_head" => model.point_head = model.point_head.no_grad(),
            "gs_head" => model.gs_head = model.gs_head.map(|m| m.no_grad()),
            "instance_head" => model.instance_head = model.instance_head.map(|m| m.no_grad()),
            "semantic_head" => model.semantic_head = model.semantic_head.map(|m| m.no_grad()),
            "sky_model" => model.sky_model = model.sky_model.map(|m| m.no_grad()),
            "motion_head" => model.motion_head = model.motion_head.map(|m| m.no_grad()),
            other => {
                return Err(TrainError::Invalid {
                    what: "optim.frozen".into(),
                    detail: format!("unknown module `{other}`"),
                });
            }
        }
    }
    Ok(model)
}

/// The parameter ids of a named top-level module (empty when the network lacks it).
fn module_ids(model: &Dggt, name: &str) -> Vec<ParamId> {
    let mut ids = IdCollector::default();
    match name {
        "aggregator" => model.aggregator.visit(&mut ids),
        "camera_head" => model.camera_head.visit(&mut ids),
        "depth_head" => model.depth_head.visit(&mut ids),
        "point_head" => model.point_head.visit(&mut ids),
        "gs_head" => model.gs_head.visit(&mut ids),
        "instance_head" => model.instance_head.visit(&mut ids),
        "semantic_head" => model.semantic_head.visit(&mut ids),
        "sky_model" => model.sky_model.visit(&mut ids),
        "motion_head" => model.motion_head.visit(&mut ids),
        _ => {}
    }
    ids.0
}

#[derive(Default)]
struct IdCollector(Vec<ParamId>);

impl ModuleVisitor for IdCollector {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.0.push(param.id);
    }
}

/// AdamW with groups and clipping.
pub struct Optimizer {
    adamw: ModuleOptimizer,
    /// Peak rate of everything outside the groups.
    base_rate: f64,
    /// Group name -> (peak rate, parameter ids).
    groups: BTreeMap<String, (f64, Vec<ParamId>)>,
    clip_norm: Option<f64>,
}

/// What one optimiser step did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepReport {
    /// Global gradient norm before clipping.
    pub grad_norm: f64,
    /// Whether the gradients were scaled down.
    pub clipped: bool,
}

impl Optimizer {
    pub fn new(config: &OptimSection, model: &Dggt) -> Self {
        let adamw = AdamWConfig::new()
            .with_beta_1(config.beta1 as f32)
            .with_beta_2(config.beta2 as f32)
            .with_epsilon(config.epsilon as f32)
            .with_weight_decay(config.weight_decay as f32)
            .init();
        let groups =
            config.groups.iter().map(|(name, &rate)| (name.clone(), (rate, module_ids(model, name)))).collect();
        Self { adamw, base_rate: config.lr, groups, clip_norm: config.clip_grad_norm }
    }

    /// Global L2 norm of `grads` over `model`'s parameters.
    pub fn grad_norm(model: &Dggt, grads: &GradientsParams) -> f64 {
        let mut norm = SquaredNorm { grads, sum: 0.0 };
        model.visit(&mut norm);
        norm.sum.sqrt()
    }

    /// Applies one step at schedule factor `factor` (the fraction of each peak rate). Returns `None` and leaves
    /// the model untouched when the gradient norm is not finite.
    pub fn step(&mut self, model: Dggt, mut grads: GradientsParams, factor: f64) -> (Dggt, Option<StepReport>) {
        let grad_norm = Self::grad_norm(&model, &grads);
        if !grad_norm.is_finite() {
            return (model, None);
        }
        let mut clipped = false;
        if let Some(limit) = self.clip_norm
            && grad_norm > limit
        {
            let mut scale = Scale { grads: &mut grads, factor: limit / grad_norm };
            model.visit(&mut scale);
            clipped = true;
        }
        let mut model = model;
        for (rate, ids) in self.groups.values() {
            let mut group = GradientsParams::new();
            let mut mover = Move { from: &mut grads, to: &mut group, ids };
            model.visit(&mut mover);
            if !group.is_empty() && *rate > 0.0 {
                model = self.adamw.step(rate * factor, model, group);
            }
        }
        if !grads.is_empty() {
            model = self.adamw.step(self.base_rate * factor, model, grads);
        }
        (model, Some(StepReport { grad_norm, clipped }))
    }

    pub fn adamw(&self) -> &ModuleOptimizer {
        &self.adamw
    }

    /// Replaces the AdamW state (from a checkpoint).
    pub fn set_adamw(&mut self, adamw: ModuleOptimizer) {
        self.adamw = adamw;
    }
}

struct SquaredNorm<'a> {
    grads: &'a GradientsParams,
    sum: f64,
}

impl ModuleVisitor for SquaredNorm<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(grad) = self.grads.get::<D>(param.id) {
            let value: f32 = grad.powi_scalar(2).sum().into_scalar();
            self.sum += value as f64;
        }
    }
}

struct Scale<'a> {
    grads: &'a mut GradientsParams,
    factor: f64,
}

impl ModuleVisitor for Scale<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(grad) = self.grads.remove::<D>(param.id) {
            self.grads.register::<D>(param.id, grad.mul_scalar(self.factor));
        }
    }
}

struct Move<'a> {
    from: &'a mut GradientsParams,
    to: &'a mut GradientsParams,
    ids: &'a [ParamId],
}

impl ModuleVisitor for Move<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if self.ids.contains(&param.id)
            && let Some(grad) = self.from.remove::<D>(param.id)
        {
            self.to.register::<D>(param.id, grad);
        }
    }
}
