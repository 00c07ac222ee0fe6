//! One configuration measured: its warm-up and timed repetitions, reduced to median stage times and the last
//! repetition's counts and renders, with a failure or panic of any row but the exact reference turned into the
//! reason it is skipped.

use std::panic::{AssertUnwindSafe, catch_unwind};

use dggt_geom::ImageSize;

use super::outcome::{SkipCounts, StageTimes};
use super::prepare::RowSetup;
use super::repetition::RepetitionOutputs;
use super::setup::{Runner, TargetImages};
use crate::error::BenchError;
use crate::knobs::{Configuration, Knobs, Precision, Varied};
use crate::precision::panic_message;

/// What one configuration's last repetition rendered, and its timings.
pub(super) struct RowRun {
    pub(super) size: ImageSize,
    pub(super) input_frames: Vec<usize>,
    pub(super) times: StageTimes,
    pub(super) gaussians_kept: f64,
    pub(super) gaussian_candidates: f64,
    pub(super) sky_gaussians: usize,
    pub(super) skipped: SkipCounts,
    /// Per target view, `[H, W, 3]` at the row's size, clamped to `[0, 1]`.
    pub(super) renders: Vec<Vec<f32>>,
    /// Per target view, the refiner's reference view `[H, W, 3]` when it takes one (see
    /// [`RowSetup::references`]).
    pub(super) references: Vec<Vec<f32>>,
}

/// Runs one configuration, a panic caught: the run, or why the row is skipped. A failure of the exact reference
/// is an error, since every other row is measured against it.
pub(super) fn measure(
    runner: &mut Runner<'_>,
    configuration: &Configuration,
    inputs: &[usize],
    targets: &[TargetImages],
) -> Result<Result<RowRun, String>, BenchError> {
    let knobs = configuration.knobs;
    let is_reference = configuration.varied == Varied::Reference;
    match catch_unwind(AssertUnwindSafe(|| runner.run(&knobs, inputs, targets))) {
        Ok(Ok(run)) => Ok(Ok(run)),
        Ok(Err(error)) if is_reference => Err(error),
        Ok(Err(error)) => Ok(Err(match knobs.precision {
            Precision::F32 => format!("failed: {error}"),
            reduced => format!("failed: the network runs in {reduced} but its outputs are unusable: {error}"),
        })),
        Err(panic) => {
            let message = panic_message(&*panic).split_whitespace().collect::<Vec<_>>().join(" ");
            if is_reference {
                return Err(BenchError::Panicked { doing: "the exact reference render", message });
            }
            Ok(Err(format!("failed: {message}")))
        }
    }
}

impl Runner<'_> {
    /// Measures one configuration with the given input frames.
    fn run(&mut self, knobs: &Knobs, inputs: &[usize], targets: &[TargetImages]) -> Result<RowRun, BenchError> {
        let setup: RowSetup = self.prepare(knobs, inputs, targets)?;
        let model = self.model(knobs.precision).clone();
        let mut samples: Vec<[f64; 4]> = Vec::new();
        let mut last: Option<RepetitionOutputs> = None;
        for repetition in 0..self.options.warmup + self.options.repeat {
            let (times, outputs) = self.repetition(&model, &setup)?;
            if repetition >= self.options.warmup {
                samples.push(times);
            }
            last = Some(outputs);
        }
        let last = last.ok_or_else(|| BenchError::setting("--repeat", "no run"))?;
        let median_of = |k: usize| median(samples.iter().map(|s| s[k]).collect());
        let times = StageTimes {
            backbone_ms: median_of(0),
            heads_ms: median_of(1),
            assembly_ms: median_of(2),
            raster_ms: median_of(3),
            total_ms: median(samples.iter().map(|s| s.iter().sum()).collect()),
        };
        let views = last.counts.len().max(1) as f64;
        Ok(RowRun {
            size: setup.size,
            input_frames: inputs.to_vec(),
            times,
            gaussians_kept: last.counts.iter().map(|c| c.kept() as f64).sum::<f64>() / views,
            gaussian_candidates: last.counts.iter().map(|c| c.candidates as f64).sum::<f64>() / views,
            sky_gaussians: last.sky_gaussians,
            skipped: last.skipped,
            renders: last.renders.into_iter().map(|r| r.into_iter().map(|v| v.clamp(0.0, 1.0)).collect()).collect(),
            references: setup.references,
        })
    }
}

/// The median (the mean of the middle two for an even count); NaN for none.
pub fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 { values[n / 2] } else { (values[n / 2 - 1] + values[n / 2]) / 2.0 }
}
