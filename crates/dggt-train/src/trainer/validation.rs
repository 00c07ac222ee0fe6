//! The run's validation: the views a watcher is shown, the weights scored (their average once it has started,
//! else the master's) on the validation scenes, and a validation pass of the run logged, recorded and shown.

use std::path::Path;

use burn::module::Module;
use dggt_model::Dggt;
use dggt_run::average::WeightAverage;
use dggt_run::compute_pool::on_pool_worker;
use dggt_run::metrics::{MetricsLog, RecordKind};
use dggt_run::progress::ProgressBar;

use super::setup::Trainer;
use crate::error::TrainError;
use crate::records::{ScoredWeights, ValidationRecord};
use crate::snapshot::{SnapshotOptions, ValidationViews};
use crate::validate::{Validation, Validator};
use crate::watch::RunWatcher;

impl Trainer {
    /// The views a validation pass pictures for a watcher, in the first validation scene.
    pub fn validation_views(&self) -> ValidationViews {
        let cameras = self.validation_scenes.first().map_or(0, |scene| scene.cameras.len());
        let views = |frames: &[usize]| -> Vec<(usize, usize)> {
            frames.iter().flat_map(|&frame| (0..cameras).map(move |c| (frame, c))).collect()
        };
        let frames = &self.config.data.validation;
        ValidationViews { inputs: views(&frames.inputs), targets: views(&frames.targets) }
    }

    /// Scores the current weights on the validation frames.
    pub fn validate(&self) -> Result<Option<Validation>, TrainError> {
        self.validate_into(None)
    }

    /// [`Trainer::validate`], writing each target's render, truth and difference as a PNG into `save_to`.
    pub fn validate_into(&self, save_to: Option<&Path>) -> Result<Option<Validation>, TrainError> {
        self.validate_weights(&self.scored_weights().1, save_to, None)
    }

    /// Scores `model` on the validation frames, writing its renders into `save_to` and picturing the first
    /// scene as `snapshot` says.
    fn validate_weights(
        &self,
        model: &Dggt,
        save_to: Option<&Path>,
        snapshot: Option<SnapshotOptions>,
    ) -> Result<Option<Validation>, TrainError> {
        let frames = &self.config.data.validation;
        if frames.inputs.is_empty() {
            return Ok(None);
        }
        let model = model.clone().fork(&self.plain_device);
        let validator = Validator {
            model: &model,
            objective: &self.objective,
            lpips: self.validation_lpips.as_ref(),
            preprocess: &self.config.data.preprocess,
            device: &self.plain_device,
            snapshot,
        };
        on_pool_worker(|| validator.scenes(&self.validation_scenes, frames, save_to))
    }

    /// The weights validation scores, without autodiff: their average once it has started, else the master's.
    pub fn scored_weights(&self) -> (ScoredWeights, Dggt) {
        match self.average.as_ref().and_then(WeightAverage::average) {
            Some(average) => (ScoredWeights::Average, average.clone()),
            None => (ScoredWeights::Trained, self.model().valid()),
        }
    }

    /// A validation pass of the run: the trained weights, and their average once it has started, each logged
    /// and recorded; the renders (into `renders`), the snapshot `watcher` asks for and the returned scores are
    /// those of the scored weights ([`Trainer::scored_weights`]), which `watcher` is also shown.
    pub(super) fn validate_and_record(
        &self,
        renders: &Path,
        mut metrics: Option<&mut MetricsLog>,
        watcher: &mut dyn RunWatcher,
        bar: &ProgressBar,
        elapsed: f64,
    ) -> Result<Option<Validation>, TrainError> {
        let (scored, scored_model) = self.scored_weights();
        let snapshot = watcher.snapshot_wanted(self.state.step);
        let mut passes = vec![(scored, scored_model, Some(renders), snapshot)];
        if scored == ScoredWeights::Average {
            passes.push((ScoredWeights::Trained, self.model().valid(), None, None));
        }
        let mut scored_validation = None;
        for (weights, model, save_to, snapshot) in passes {
            let Some(validation) = self.validate_weights(&model, save_to, snapshot)? else { return Ok(None) };
            let step = self.state.step;
            tracing::info!(step, psnr = validation.psnr, ssim = validation.ssim, ?weights, "validation");
            if let Some(metrics) = metrics.as_deref_mut() {
                metrics.append(
                    RecordKind::Validation,
                    &ValidationRecord { step, weights, validation: &validation, time_s: elapsed },
                )?;
            }
            let (count, scores) = (validation.scenes.len(), validation.scores_line());
            bar.println(match weights {
                ScoredWeights::Trained if scored == ScoredWeights::Trained => {
                    format!("validation at step {step} on {count} scene(s): {scores}")
                }
                ScoredWeights::Trained => format!("  the trained weights: {scores}"),
                ScoredWeights::Average => {
                    format!("validation at step {step} on {count} scene(s), the average of the weights: {scores}")
                }
            });
            if weights == scored {
                watcher.validation(step, &validation);
                scored_validation = Some(validation);
            }
        }
        Ok(scored_validation)
    }
}
