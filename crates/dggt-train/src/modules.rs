//! The network's top-level modules by name, as `optim.frozen` and `optim.groups` name them: freezing them, and
//! the optimiser whose groups are their parameters.

use std::collections::HashMap;

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::tensor::Tensor;
use dggt_model::Dggt;
use dggt_run::{OptimSection, Optimizer};

use crate::error::TrainError;

/// The network's top-level modules, which `optim.frozen` and `optim.groups` name.
pub const MODULES: [&str; 10] = [
    "aggregator",
    "camera_head",
    "depth_head",
    "point_head",
    "gs_head",
    "instance_head",
    "semantic_head",
    "sky_model",
    "motion_head",
    "flow_head",
];

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
            "flow_head" => model.flow_head = model.flow_head.map(|m| m.no_grad()),
            other => {
                return Err(TrainError::Setting {
                    setting: "optim.frozen",
                    detail: format!("unknown module `{other}`"),
                });
            }
        }
    }
    Ok(model)
}

/// The optimiser of `model` for `config`: the parameters of every module in `config.groups` at that group's
/// rate, all others at `config.lr`.
pub fn grouped_optimizer(config: &OptimSection, model: &Dggt) -> Optimizer {
    let group_rates: HashMap<ParamId, f64> = config
        .groups
        .iter()
        .flat_map(|(name, &rate)| module_ids(model, name).into_iter().map(move |id| (id, rate)))
        .collect();
    Optimizer::grouped(config, group_rates)
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
        "flow_head" => model.flow_head.visit(&mut ids),
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
