//! Stress cases through the network itself (the tiny architecture, fresh weights): black, white and
//! one-colour images, all-sky and sky-free masks, a single input frame and 64 input frames, with the camera
//! head's own (untrained) poses, through rendering, the objective (camera and depth terms included) and the
//! backward pass to every parameter. The model may be cast to f16 or bf16 ([`Dggt::with_float_dtype`]); its
//! outputs then enter the scene in f32, and the gradients land on the reduced-precision parameters.

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Gradients, Tensor};
use dggt_infer::RenderSection;
use dggt_model::Dggt;
use dggt_objective::{Forward, Objective};

use crate::error::StressError;
use crate::pipeline::render_and_differentiate;
use crate::probe::{Probe, Stage};
use crate::scenario::Scenario;

/// Runs the network on the scenario's inputs, renders, and differentiates the objective.
pub fn run(
    probe: &mut Probe,
    scenario: &Scenario,
    model: &Dggt,
    objective: &Objective,
    render: &RenderSection,
    device: &Device,
) -> Result<(), StressError> {
    let batch = scenario.batch(device);
    let forward = Forward::run(model, &batch, render)?;
    probe.tensor(Stage::Network, "depth", &forward.depth);
    if let Some(logit) = &forward.dynamic_logit {
        probe.tensor(Stage::Network, "dynamic logits", logit);
    }
    for (i, encoding) in forward.encodings.iter().enumerate() {
        probe.tensor(Stage::Network, &format!("camera encoding, iteration {i}"), encoding);
    }
    let grads = render_and_differentiate(probe, objective, &forward, &batch)?;
    let reached = probe_parameter_gradients(probe, model, &grads);
    probe.require(Stage::Gradients, "parameters", reached > 0, "no parameter received a gradient");
    Ok(())
}

/// Probes the gradient of every parameter that has one; returns how many had one.
fn probe_parameter_gradients(probe: &mut Probe, model: &Dggt, grads: &Gradients) -> usize {
    struct Visitor<'a> {
        probe: &'a mut Probe,
        grads: &'a Gradients,
        path: Vec<String>,
        reached: usize,
    }
    impl ModuleVisitor for Visitor<'_> {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            if let Some(grad) = param.val().grad(self.grads) {
                self.reached += 1;
                self.probe.tensor(Stage::Gradients, &format!("grad {}", self.path.join(".")), &grad);
            }
        }
    }
    let mut visitor = Visitor { probe, grads, path: Vec::new(), reached: 0 };
    model.visit(&mut visitor);
    visitor.reached
}
