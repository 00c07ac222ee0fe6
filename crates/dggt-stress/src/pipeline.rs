//! The stages every rendering case shares: read the Gaussians a forward pass placed, render the batch's views,
//! compute the training objective and its gradients, probing each stage's tensors on the way.

use burn::tensor::{Gradients, Tensor};
use dggt_objective::{Forward, Objective, StepBatch, ViewsToRender};

use crate::error::StressError;
use crate::probe::{Probe, Stage};

/// Probes the per-pixel and sky Gaussians of `forward`.
pub(crate) fn probe_gaussians(probe: &mut Probe, forward: &Forward) {
    let pixels = forward.pixels();
    for (name, tensor) in [
        ("pixels.means", &pixels.means),
        ("pixels.quats_wxyz", &pixels.quats_wxyz),
        ("pixels.scales", &pixels.scales),
        ("pixels.colors", &pixels.colors),
    ] {
        probe.tensor(Stage::Gaussians, name, tensor);
    }
    probe.tensor(Stage::Gaussians, "pixels.opacity", &pixels.opacity);
    probe.tensor(Stage::Gaussians, "pixels.lifespan", &pixels.lifespan);
    if let Some(logit) = &pixels.dynamic_logit {
        probe.tensor(Stage::Gaussians, "pixels.dynamic_logit", logit);
    }
    if let Some(sky) = &forward.scene.sky {
        for (name, tensor) in [
            ("sky.colors", &sky.colors),
            ("sky.means", &sky.means),
            ("sky.scales", &sky.scales),
            ("sky.quats", &sky.quats),
        ] {
            probe.tensor(Stage::Gaussians, name, tensor);
        }
        probe.tensor(Stage::Gaussians, "sky.opacities", &sky.opacities);
    }
}

/// Renders every view of `batch`, computes the objective and its gradients; returns the gradients.
pub(crate) fn render_and_differentiate(
    probe: &mut Probe,
    objective: &Objective,
    forward: &Forward,
    batch: &StepBatch,
) -> Result<Gradients, StressError> {
    probe_gaussians(probe, forward);
    let views = objective.render_views(forward, batch, ViewsToRender::TargetsAndInputs)?;
    for view in &views {
        let kind = if view.is_target { "target" } else { "input" };
        probe.tensor(Stage::Render, &format!("{kind} {} rgb", view.truth_index), &view.rgb);
        probe.tensor(Stage::Render, &format!("{kind} {} alpha", view.truth_index), &view.alpha);
    }
    let loss = objective.loss_of(forward, batch)?;
    for (term, value) in &loss.terms {
        probe.values(Stage::Losses, term.name(), [*value]);
    }
    probe.tensor(Stage::Losses, "total", &loss.total);
    Ok(loss.total.backward())
}

/// Probes the gradient of `tensor` (created with `require_grad`), which must exist.
pub(crate) fn probe_gradient<const D: usize>(probe: &mut Probe, grads: &Gradients, what: &str, tensor: &Tensor<D>) {
    match tensor.grad(grads) {
        Some(grad) => probe.tensor(Stage::Gradients, &format!("grad {what}"), &grad),
        None => probe.require(Stage::Gradients, &format!("grad {what}"), false, "no gradient reached it"),
    }
}
