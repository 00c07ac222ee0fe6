//! The records a DGGT run writes to `metrics.jsonl` ([`dggt_run::metrics`]): one per optimiser step
//! ([`LoggedStep`], around the [`StepRecord`] a step returns) and one per validation pass
//! ([`ValidationRecord`]). Each is serialised once, as it is written; a key is absent when the step did not
//! measure it (no `loss` for a step skipped before its losses were summed, no `grad_norm` for one skipped
//! before its update), and a value that is not finite is written as `null`.

use std::collections::BTreeMap;

use dggt_run::divergence::StepFailure;
use dggt_run::optimizer::StepReport;
use serde::Serialize;

use crate::validate::Validation;

/// What one optimiser step did and measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepRecord {
    pub step: u64,
    /// The schedule's factor of each group's peak rate.
    pub lr_factor: f64,
    /// The update computed (applied or rolled back); absent for a step skipped before it.
    #[serde(flatten)]
    pub update: Option<UpdateRecord>,
    /// The samples' losses and timings; absent when a sample's loss was not finite.
    #[serde(flatten)]
    pub measures: Option<StepMeasures>,
    /// Why the step made no update, when it did not.
    #[serde(flatten)]
    pub failure: Option<FailureRecord>,
    /// Seconds the step took.
    pub step_s: f64,
}

/// The gradient of a step that computed an update.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct UpdateRecord {
    /// Global gradient norm before clipping.
    pub grad_norm: f64,
    /// Whether the gradients were scaled down.
    pub clipped: bool,
}

impl From<StepReport> for UpdateRecord {
    fn from(report: StepReport) -> Self {
        Self { grad_norm: report.grad_norm, clipped: report.clipped }
    }
}

/// A step's metrics: the samples' means, the Gaussians kept summed over them, seconds per stage.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct StepMeasures {
    /// The weighted loss.
    pub loss: f64,
    /// Each loss term, unweighted, by name.
    pub terms: BTreeMap<String, f64>,
    pub target_psnr: f64,
    pub gaussians_kept: usize,
    /// Seconds per stage (`batch`, `forward_and_render`, `backward`, `update`), summed over the samples.
    #[serde(rename = "stage_s")]
    pub stage_seconds: BTreeMap<String, f64>,
}

/// Why a step made no update, under the key that says what became of it.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureRecord {
    /// The update made the named tensor non-finite and was undone.
    RolledBack(String),
    /// The step was skipped before its update.
    Skipped(SkipReason),
}

/// Why a step was skipped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum SkipReason {
    #[serde(rename = "non-finite loss")]
    NonFiniteLoss,
    #[serde(rename = "non-finite gradient")]
    NonFiniteGradient,
    /// The loss jumped far above the recent ones (`optim.skip_loss_spikes`).
    #[serde(rename = "loss spike")]
    LossSpike,
}

impl std::fmt::Display for SkipReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::NonFiniteLoss => "non-finite loss",
            Self::NonFiniteGradient => "non-finite gradient",
            Self::LossSpike => "loss spike",
        })
    }
}

impl From<&StepFailure> for FailureRecord {
    fn from(failure: &StepFailure) -> Self {
        match failure {
            StepFailure::RolledBack(tensor) => Self::RolledBack(tensor.to_string()),
            StepFailure::NonFiniteGradient => Self::Skipped(SkipReason::NonFiniteGradient),
            StepFailure::NonFiniteLoss => Self::Skipped(SkipReason::NonFiniteLoss),
            StepFailure::LossSpike(_) => Self::Skipped(SkipReason::LossSpike),
        }
    }
}

impl StepRecord {
    /// The loss, when the step measured a finite one.
    pub fn finite_loss(&self) -> Option<f64> {
        self.measures.as_ref().map(|m| m.loss).filter(|loss| loss.is_finite())
    }

    /// The target PSNR, when the step measured a finite one.
    pub fn finite_target_psnr(&self) -> Option<f64> {
        self.measures.as_ref().map(|m| m.target_psnr).filter(|psnr| psnr.is_finite())
    }
}

/// A step's record as the run writes it: with the scenes its samples came from, the samples that failed to
/// load so far and the run's training seconds.
#[derive(Debug, Serialize)]
pub struct LoggedStep<'a> {
    #[serde(flatten)]
    pub record: &'a StepRecord,
    pub scenes: Vec<String>,
    pub bad_samples: u64,
    pub time_s: f64,
}

/// A validation pass as the run writes it: the step it validated, its scores and the run's training seconds.
#[derive(Debug, Serialize)]
pub struct ValidationRecord<'a> {
    pub step: u64,
    /// Whose renders were scored.
    pub weights: ScoredWeights,
    #[serde(flatten)]
    pub validation: &'a Validation,
    pub time_s: f64,
}

/// The weights a validation pass scores: the trained ones, or their average once `optim.average` has started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ScoredWeights {
    Trained,
    Average,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(value: &serde_json::Value) -> Vec<&str> {
        value.as_object().unwrap().keys().map(String::as_str).collect()
    }

    #[test]
    fn a_logged_step_has_the_keys_of_what_it_measured() {
        let measures = StepMeasures { loss: f64::NAN, target_psnr: 20.0, ..StepMeasures::default() };
        let trained = StepRecord {
            step: 3,
            lr_factor: 0.5,
            update: Some(UpdateRecord { grad_norm: 2.0, clipped: true }),
            measures: Some(measures),
            failure: None,
            step_s: 0.25,
        };
        let logged = LoggedStep { record: &trained, scenes: vec!["s0".into()], bad_samples: 1, time_s: 9.0 };
        let value = serde_json::to_value(&logged).unwrap();
        let mut expected = vec![
            "bad_samples",
            "clipped",
            "gaussians_kept",
            "grad_norm",
            "loss",
            "lr_factor",
            "scenes",
            "stage_s",
            "step",
            "step_s",
            "target_psnr",
            "terms",
            "time_s",
        ];
        assert_eq!(keys(&value), expected, "{value}");
        assert!(value["loss"].is_null(), "a loss that is not finite is written as null: {value}");

        let skipped = StepRecord {
            update: None,
            measures: None,
            failure: Some(FailureRecord::Skipped(SkipReason::NonFiniteLoss)),
            ..trained.clone()
        };
        let value = serde_json::to_value(&skipped).unwrap();
        expected = vec!["lr_factor", "skipped", "step", "step_s"];
        assert_eq!(keys(&value), expected, "{value}");
        assert_eq!(value["skipped"], "non-finite loss");
        let rolled_back = StepRecord { failure: Some(FailureRecord::RolledBack("weight `w`".into())), ..trained };
        let value = serde_json::to_value(&rolled_back).unwrap();
        assert_eq!(value["rolled_back"], "weight `w`", "{value}");
        assert!(value.get("skipped").is_none() && value["grad_norm"] == 2.0, "{value}");
    }
}
