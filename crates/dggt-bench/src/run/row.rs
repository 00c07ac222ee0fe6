//! One configuration's outcome: skipped (the backend lacks its precision, the scene has too few frames, or its
//! run failed), or measured and scored against the exact render and the truth, refined when there is a refiner.

use super::measure::measure;
use super::outcome::{MeasuredRow, RefinedRow, RowOutcome};
use super::refine::refine_renders;
use super::score::{compare, resize_rgb};
use super::setup::Sweep;
use crate::error::BenchError;
use crate::knobs::{Configuration, Varied};
use crate::precision::precision_support;

impl Sweep<'_> {
    /// Measures and scores `configuration`, or says why it is skipped. The exact reference must come first:
    /// every other row is scored against it.
    pub(super) fn row(&mut self, configuration: Configuration) -> Result<RowOutcome, BenchError> {
        let options = self.runner.options;
        let device = self.runner.device;
        let knobs = configuration.knobs;
        let supported =
            self.support.entry(knobs.precision).or_insert_with(|| precision_support(device, knobs.precision));
        if let Err(reason) = supported.clone() {
            return Ok(RowOutcome::Skipped { configuration, reason: reason.to_string() });
        }
        let inputs = match self.runner.plan.inputs(knobs.input_frames) {
            Ok(inputs) => inputs,
            Err(reason) => return Ok(RowOutcome::Skipped { configuration, reason: reason.to_string() }),
        };
        tracing::info!("measuring {} ({})", knobs.label(), configuration.varied.name());
        let run = match measure(&mut self.runner, &configuration, &inputs, &self.targets)? {
            Ok(run) => run,
            Err(reason) => return Ok(RowOutcome::Skipped { configuration, reason }),
        };
        let (reference_size, lpips) = (self.reference_size, self.lpips.as_ref());
        let at_reference: Vec<Vec<f32>> =
            run.renders.iter().map(|image| resize_rgb(image, run.size, reference_size)).collect();
        if configuration.varied == Varied::Reference {
            self.exact = Some(at_reference.clone());
        }
        let exact = self.exact.as_ref().ok_or_else(|| BenchError::Missing("sweep: the exact reference runs first"))?;
        let vs_exact = compare(&at_reference, exact, reference_size, lpips, device)?;
        let truth: Vec<Vec<f32>> = self.targets.iter().map(|t| t.truth.clone()).collect();
        let vs_truth = compare(&at_reference, &truth, reference_size, lpips, device)?;
        let refined = match (&self.refiner, &options.refine) {
            (Some(refiner), Some(spec)) => {
                let (refine_ms, images) = refine_renders(refiner, spec.latent, &run, options.repeat, device)?;
                let at_reference: Vec<Vec<f32>> =
                    images.iter().map(|image| resize_rgb(image, run.size, reference_size)).collect();
                let vs_truth = compare(&at_reference, &truth, reference_size, lpips, device)?;
                Some(RefinedRow { refine_ms, vs_truth })
            }
            _ => None,
        };
        Ok(RowOutcome::Measured(MeasuredRow {
            configuration,
            size: run.size,
            input_frames: run.input_frames,
            times: run.times,
            gaussians_kept: run.gaussians_kept,
            gaussian_candidates: run.gaussian_candidates,
            sky_gaussians: run.sky_gaussians,
            skipped: run.skipped,
            vs_exact,
            vs_truth,
            pareto_vs_exact: false,
            pareto_vs_truth: false,
            refined,
        }))
    }
}
