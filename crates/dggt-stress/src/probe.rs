//! Finding bad values: a [`Probe`] reads tensors and host values at named stages of the pipeline and records
//! each one that holds a NaN or an infinity (or breaks a stated invariant), with how many of its values do.

use std::fmt;

use burn::tensor::Tensor;
use dggt_model::host::host_f32;
use serde::Serialize;

/// Where in the pipeline a value was read, in data-flow order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Poses, interpolation and timelines (host, `f64`).
    Geometry,
    /// The network's outputs.
    Network,
    /// The activated per-pixel Gaussians and the sky Gaussians.
    Gaussians,
    /// Rendered colours and alpha.
    Render,
    /// Every loss term and the weighted total.
    Losses,
    /// Gradients of the parameters or of the hand-made predictions.
    Gradients,
}

impl Stage {
    pub const ALL: [Stage; 6] =
        [Stage::Geometry, Stage::Network, Stage::Gaussians, Stage::Render, Stage::Losses, Stage::Gradients];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Geometry => "geometry",
            Stage::Network => "network",
            Stage::Gaussians => "gaussians",
            Stage::Render => "render",
            Stage::Losses => "losses",
            Stage::Gradients => "gradients",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One value (tensor, scalar or invariant) that went wrong.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    pub stage: Stage,
    /// The tensor or quantity, e.g. `pixels.scales` or `grad aggregator.patch_embed.proj.weight`.
    pub what: String,
    /// Bad values among `total`.
    pub bad: usize,
    pub total: usize,
    /// What was wrong: `non-finite`, or the broken invariant.
    pub detail: String,
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "[{}] {}: {} of {} values {}", self.stage, self.what, self.bad, self.total, self.detail)
    }
}

/// Collects findings; counts what it checked so a report can show that something was read at each stage.
#[derive(Debug, Default)]
pub struct Probe {
    findings: Vec<Finding>,
    checked: [usize; Stage::ALL.len()],
}

impl Probe {
    /// Checks every value of `tensor` (read back to the host as `f32`).
    pub fn tensor<const D: usize>(&mut self, stage: Stage, what: &str, tensor: &Tensor<D>) {
        match host_f32(tensor.clone(), what) {
            Ok(values) => self.values(stage, what, values.iter().map(|&v| f64::from(v))),
            Err(error) => self.findings.push(Finding {
                stage,
                what: what.to_string(),
                bad: tensor.shape().num_elements(),
                total: tensor.shape().num_elements(),
                detail: format!("unreadable: {}", error.detail),
            }),
        }
    }

    /// Checks host values.
    pub fn values(&mut self, stage: Stage, what: &str, values: impl IntoIterator<Item = f64>) {
        let (mut bad, mut total) = (0, 0);
        for value in values {
            total += 1;
            bad += usize::from(!value.is_finite());
        }
        self.checked[stage as usize] += total;
        if bad > 0 {
            self.findings.push(Finding { stage, what: what.to_string(), bad, total, detail: "non-finite".into() });
        }
    }

    /// Records a broken invariant (`holds` false), such as a rotation that is no longer a unit quaternion.
    pub fn require(&mut self, stage: Stage, what: &str, holds: bool, detail: impl Into<String>) {
        self.checked[stage as usize] += 1;
        if !holds {
            self.findings.push(Finding { stage, what: what.to_string(), bad: 1, total: 1, detail: detail.into() });
        }
    }

    /// Values checked at `stage`.
    pub fn checked(&self, stage: Stage) -> usize {
        self.checked[stage as usize]
    }

    pub fn findings(&self) -> &[Finding] {
        &self.findings
    }

    pub fn into_findings(self) -> Vec<Finding> {
        self.findings
    }
}
