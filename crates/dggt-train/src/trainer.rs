//! The training loop.
//!
//! Each optimiser step draws `accumulation` samples for every device (sample `k = step · samples_per_step + j`,
//! a pure function of the seed; a run of several processes draws each rank's share, [`ranks`]); every device
//! computes its samples' losses and gradients on its own replica of the network (one thread each), the
//! gradients are all-reduced ([`replicas`](crate::replicas), then across ranks,
//! [`rank_gradients`](crate::rank_gradients)), and every
//! replica clips the global norm and steps AdamW per parameter group at the scheduled rate. A sample with
//! a non-finite loss or network output (a depth that overflowed, say), or a step with a non-finite gradient
//! norm, is skipped with a warning and leaves the weights untouched; an update that makes a weight or moment
//! non-finite is rolled back; a checkpoint falling due meanwhile waits for a step that trains, and too many
//! such steps in a row stop the run ([`divergence`]). With `optim.skip_loss_spikes`, a step whose loss jumps far
//! above the recent ones makes no update either ([`spikes`]); with `optim.average`, an average of the weights is
//! kept beside them ([`average`]). Metrics go to
//! `metrics.jsonl` ([`records`](crate::records)), checkpoints to `checkpoints/` (see [`checkpoint`]); an error
//! of a validation pass names the step it validated. Of several ranks, rank 0 alone writes them, validates and
//! draws the progress bar.
//!
//! [`checkpoint`]: crate::checkpoint
//! [`average`]: dggt_run::average
//! [`ranks`]: crate::ranks

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use burn::module::Module;
use burn::optim::{GradientsAccumulator, GradientsParams};
use burn::tensor::Device;
use dggt_collective::ProcessGroup;
use dggt_data::{
    DatasetIndex, DatasetSampling, IndexedScene, LoadedSample, LoaderOptions, Prefetcher, SceneMix, Split,
    dataset_stream,
};
use dggt_infer::{StartingWeights, fresh_model};
use dggt_losses::{Lpips, LpipsKind};
use dggt_model::{Dggt, ModelConfig};
use dggt_objective::{DepthFlowMaps, LossTerm, Objective, StepBatch};
use dggt_run::average::WeightAverage;
use dggt_run::checkpoint::{Purpose, RunState, Weights, optimizer_file};
use dggt_run::divergence::{self, CheckpointDue, CheckpointGate, DivergenceLimit, StepFailure};
use dggt_run::metrics::{MetricsLog, RecordKind};
use dggt_run::progress::{ProgressBar, Visibility, progress_bar, styled_bar};
use dggt_run::schedule::WarmupCosine;
use dggt_run::spikes::{self, Spike};
use dggt_run::{Start, failpoint, run_folder};

use crate::checkpoint;
use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::modules::{freeze, grouped_optimizer};
use crate::rank_gradients::{GradientTransport, sum_over_ranks};
use crate::ranks;
use crate::records::{FailureRecord, LoggedStep, ScoredWeights, StepMeasures, StepRecord, ValidationRecord};
use crate::replicas::{Replica, Replicas};
use crate::resume::{self, AllowedChanges, ConfiguredSections};
use crate::snapshot::{SnapshotOptions, ValidationViews};
use crate::validate::{Validation, Validator};
use crate::watch::{RunWatcher, Unwatched};

/// The cached scene index in a run's output folder. It is not among the run's own files
/// ([`run_folder::RUN_ENTRIES`]): it is checked against the scenes on every use and rebuilt when stale, and a
/// dry run writes it before any step.
pub const SCENE_INDEX: &str = "scene-index.json";

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    pub steps_run: u64,
    pub final_step: u64,
    pub skipped_steps: u64,
    /// Steps whose update was undone for making a weight non-finite.
    pub rolled_back_steps: u64,
    pub first_loss: Option<f64>,
    pub last_loss: Option<f64>,
    pub first_target_psnr: Option<f64>,
    pub last_target_psnr: Option<f64>,
    pub validation: Option<Validation>,
    pub elapsed_s: f64,
    pub checkpoint: Option<PathBuf>,
}

/// Options of [`Trainer::run`] beyond the configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunOptions {
    /// Whether the progress bar is drawn on stderr.
    pub progress: Visibility,
    /// Stop after this step even if the configuration runs longer (for interrupting runs on purpose).
    pub stop_after: Option<u64>,
}

pub struct Trainer {
    config: TrainConfig,
    model_config: ModelConfig,
    /// The indexed scenes and how each sample draws from them.
    sampling: DatasetSampling,
    /// Scored by [`Trainer::validate`]: the held-out scenes, or the first training scene.
    validation_scenes: Vec<IndexedScene>,
    objective: Objective,
    /// The network and optimiser on every training device (with autodiff); the first is the master.
    replicas: Replicas,
    /// The first device without autodiff (validation).
    plain_device: Device,
    /// LPIPS-Alex for validation, when configured.
    validation_lpips: Option<Lpips>,
    state: RunState,
    /// Why the last step failed, when it did.
    last_failure: Option<StepFailure>,
    /// Holds back checkpoints while steps fail.
    checkpoint_gate: CheckpointGate,
    /// The average of the master's weights (`optim.average`; rank 0 alone keeps it).
    average: Option<WeightAverage<Dggt>>,
    /// The processes of the run (this one alone, or the ranks of an MPI job).
    group: ProcessGroup,
    /// How the ranks' gradients travel (host buffers, or NCCL on CUDA devices).
    transport: GradientTransport,
}

impl Trainer {
    /// Builds a run of `config` (validated here) on `devices` (at least one), started as `start` says, in this
    /// process alone.
    pub fn new(config: TrainConfig, devices: Vec<Device>, start: Start) -> Result<Self, TrainError> {
        Self::in_group(config, devices, start, ProcessGroup::Single, &AllowedChanges::none())
    }

    /// [`Trainer::new`] as one rank of `group`: every rank calls it with the same configuration; rank 0 checks
    /// and prepares the output folder and names the checkpoint every rank resumes. A resume may change the
    /// settings of what the network sees that `allowed` names ([`resume`]).
    pub fn in_group(
        config: TrainConfig,
        devices: Vec<Device>,
        start: Start,
        group: ProcessGroup,
        allowed: &AllowedChanges,
    ) -> Result<Self, TrainError> {
        config.validate()?;
        let plain_device = devices.first().cloned().ok_or(TrainError::NoDevice)?;
        let autodiff: Vec<Device> = devices.iter().map(|d| d.clone().autodiff()).collect();
        let device = autodiff[0].clone();
        // The folder is checked before anything is written into it.
        let checkpoints = config.run.out_dir.join(run_folder::CHECKPOINTS);
        let (resume_from, (sampling, validation_scenes)) = ranks::agree_on_start(
            &group,
            &checkpoints,
            || Ok((resume_point(&config, start, allowed)?, index_datasets(&config)?)),
            || index_datasets(&config),
        )?;
        let objective = Objective::new(config.loss.clone(), config.render.clone(), &device)?;

        let (model, model_config, optimizer, state, average) = match resume_from {
            Some(dir) => {
                let model_config = checkpoint::read_model_config(&dir)?;
                let blank = Dggt::new(&model_config, &device)?;
                let loaded = checkpoint::load(&dir, blank)?;
                let model = freeze(loaded.model, &config.optim.frozen)?;
                let mut optimizer = grouped_optimizer(&config.optim, &model);
                optimizer.load(&optimizer_file(&dir), &device)?;
                tracing::info!(checkpoint = %dir.display(), step = loaded.state.step, "resuming");
                (model, loaded.config, optimizer, loaded.state, loaded.average)
            }
            None => {
                let model_config = config.model.architecture();
                let init = config
                    .model
                    .init_checkpoint
                    .as_deref()
                    .map(|path| StartingWeights { path, may_lack: &config.model.init_may_lack });
                let model = fresh_model(&model_config, init, config.run.seed, &device)?;
                let model = freeze(model, &config.optim.frozen)?;
                let optimizer = grouped_optimizer(&config.optim, &model);
                let state = RunState::starting(config.run.seed, 0);
                (model, model_config, optimizer, state, None)
            }
        };
        if state.seed != config.run.seed {
            return Err(TrainError::SeedChanged { checkpoint: state.seed, configured: config.run.seed });
        }
        let mut state = state;
        let samples_per_step = config.optim.accumulation as u64 * autodiff.len() as u64 * group.size() as u64;
        if state.samples_per_step != 0 && state.samples_per_step != samples_per_step {
            tracing::warn!(
                before = state.samples_per_step,
                now = samples_per_step,
                "resuming with another number of samples per step (optim.accumulation x devices x ranks): the run continues \
                 on a different sample sequence than the uninterrupted run would"
            );
        }
        state.samples_per_step = samples_per_step;
        let validation_lpips = validation_lpips(&config, &plain_device)?;
        let average = weight_average(&config, average, &group);
        let transport = GradientTransport::agree(&group, &plain_device)?;
        Ok(Self {
            config,
            model_config,
            sampling,
            validation_scenes,
            objective,
            replicas: Replicas::new(model, optimizer, &autodiff),
            validation_lpips,
            plain_device,
            state,
            last_failure: None,
            checkpoint_gate: CheckpointGate::default(),
            average,
            group,
            transport,
        })
    }

    /// The master replica's network.
    pub fn model(&self) -> &Dggt {
        &self.replicas.master().model
    }

    /// The network and optimiser on every training device.
    pub fn replicas(&self) -> &Replicas {
        &self.replicas
    }

    /// Samples drawn per optimiser step: `optim.accumulation` on every device of every rank.
    pub fn samples_per_step(&self) -> u64 {
        self.state.samples_per_step
    }

    /// Samples this process draws per optimiser step: `optim.accumulation` on each of its devices.
    pub fn local_samples_per_step(&self) -> u64 {
        self.state.samples_per_step / self.group.size() as u64
    }

    /// The processes of the run.
    pub fn group(&self) -> &ProcessGroup {
        &self.group
    }

    pub fn model_config(&self) -> &ModelConfig {
        &self.model_config
    }

    pub fn state(&self) -> &RunState {
        &self.state
    }

    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// The learning-rate schedule as factors of each group's peak rate.
    pub fn schedule(&self) -> WarmupCosine {
        let o = &self.config.optim;
        WarmupCosine { peak: 1.0, warmup: o.warmup_steps, total: self.config.run.steps, min_ratio: o.min_lr_ratio }
    }

    /// The objective that renders the run's views.
    pub fn objective(&self) -> &Objective {
        &self.objective
    }

    /// The run's scene index.
    pub fn index(&self) -> &DatasetIndex {
        &self.sampling.index
    }

    /// The indexed scenes and how each sample draws from them ([`Trainer::sample`] loads from them).
    pub fn sampling(&self) -> &DatasetSampling {
        &self.sampling
    }

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
        validator.scenes(&self.validation_scenes, frames, save_to)
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
    fn validate_and_record(
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

    /// The sample drawn for sample index `index` (`step · samples_per_step + j`), decoded.
    pub fn sample(&self, index: u64) -> Result<LoadedSample, TrainError> {
        Ok(self.sampling.load(&self.config.data.preprocess, index)?)
    }

    /// Trains until `run.steps` (or the time limit, or `options.stop_after`), checkpointing on the way.
    pub fn run(&mut self, options: RunOptions) -> Result<RunSummary, TrainError> {
        self.run_watched(options, &mut Unwatched)
    }

    /// [`Trainer::run`], showing `watcher` every step and validation pass (on the writing rank).
    pub fn run_watched(&mut self, options: RunOptions, watcher: &mut dyn RunWatcher) -> Result<RunSummary, TrainError> {
        let run = self.config.run.clone();
        let writer = self.group.is_writer();
        let mut metrics = match writer {
            true => {
                fs::create_dir_all(&run.out_dir)
                    .map_err(|source| TrainError::Io { path: run.out_dir.clone(), source })?;
                Some(MetricsLog::continuing_at(&run.out_dir.join(run_folder::METRICS), self.state.step)?)
            }
            false => None,
        };

        let local = self.local_samples_per_step();
        let positions = ranks::sample_positions(self.state.step, local, self.group.rank(), self.group.size());
        let options_loader =
            LoaderOptions { workers: self.config.data.workers.max(1), capacity: 2 * self.config.data.workers.max(1) };
        let mut stream = dataset_stream(self.sampling.clone(), self.config.data.preprocess, positions, options_loader)?;

        let last_step = options.stop_after.map_or(run.steps, |s| s.min(run.steps));
        let visibility = if writer { options.progress } else { Visibility::Hidden };
        let bar = progress_bar(visibility, self.state.step, run.steps);
        let started = Instant::now();
        let elapsed_before = self.state.elapsed_s;
        let schedule = self.schedule();
        let mut summary = RunSummary {
            steps_run: 0,
            final_step: self.state.step,
            skipped_steps: self.state.skipped_steps,
            rolled_back_steps: self.state.rolled_back_steps,
            first_loss: None,
            last_loss: None,
            first_target_psnr: None,
            last_target_psnr: None,
            validation: None,
            elapsed_s: elapsed_before,
            checkpoint: None,
        };
        let loss = &self.config.loss;
        let maps = if loss.depth > 0.0 || loss.flow > 0.0 || loss.learnt_flow > 0.0 {
            DepthFlowMaps::Read
        } else {
            DepthFlowMaps::Skip
        };

        while self.state.step < last_step {
            let step = self.state.step;
            failpoint::exit_before_step(self.group.rank(), step);
            let samples = (0..local).map(|_| next_sample(&mut stream)).collect::<Result<Vec<_>, _>>()?;
            self.count_bad_samples(&samples)?;
            let record = self.train_step(&samples, schedule.factor(step), maps)?;
            let pose_warmup = step < self.config.optim.pose_warmup_steps;
            if pose_warmup {
                bar.set_message(format!("pose warm-up: camera loss {:.4}", record.finite_loss().unwrap_or(f64::NAN)));
            } else if let Some(loss) = record.finite_loss() {
                let psnr = record.finite_target_psnr().unwrap_or(f64::NAN);
                summary.first_loss.get_or_insert(loss);
                summary.first_target_psnr.get_or_insert(psnr);
                summary.last_loss = Some(loss);
                summary.last_target_psnr = Some(psnr);
                bar.set_message(format!("loss {loss:.4}  target PSNR {psnr:.2} dB"));
            }
            summary.steps_run += 1;
            let elapsed = elapsed_before + started.elapsed().as_secs_f64();
            self.state.elapsed_s = elapsed;
            let logged = LoggedStep {
                record: &record,
                scenes: samples.iter().map(|s| s.scene.name.clone()).collect(),
                bad_samples: self.state.bad_samples,
                time_s: elapsed,
            };
            if let Some(metrics) = &mut metrics {
                metrics.append(RecordKind::Train, &logged)?;
                watcher.step(&logged);
            }
            bar.inc(1);
            // No checkpoint then: the weights are those the last one holds, and a new one could prune it.
            self.check_divergence()?;

            let out_of_time = run.time_limit_s.is_some_and(|limit| started.elapsed().as_secs_f64() >= limit);
            let done = self.state.step >= last_step
                || (run.time_limit_s.is_some() && ranks::rank_zero_decides(&self.group, out_of_time));
            let due = match (done, self.state.step.is_multiple_of(run.checkpoint_every)) {
                (true, _) => CheckpointDue::EndOfRun,
                (false, true) => CheckpointDue::Periodic,
                (false, false) => CheckpointDue::No,
            };
            // Saved before validating, so that a failing validation never loses the step's weights.
            if self.checkpoint_gate.write_now(&self.state, due) && writer {
                summary.checkpoint = Some(self.save_checkpoint()?);
            }
            let validate_now = (run.validate_every > 0 && self.state.step.is_multiple_of(run.validate_every)) || done;
            if validate_now && writer {
                let renders = run.out_dir.join(run_folder::VALIDATION).join(format!("step-{:08}", self.state.step));
                let validated = self
                    .validate_and_record(&renders, metrics.as_mut(), watcher, &bar, elapsed)
                    .map_err(|source| TrainError::Validation { step: self.state.step, source: Box::new(source) })?;
                summary.validation = validated.or(summary.validation.take());
            }
            if done {
                break;
            }
        }
        bar.finish_and_clear();
        if self.group.size() > 1 {
            let checksum = ranks::check_in_step(&self.group, self.model())?;
            tracing::info!(ranks = self.group.size(), "every rank holds the same weights (checksum {checksum:016x})");
        }
        summary.final_step = self.state.step;
        summary.skipped_steps = self.state.skipped_steps;
        summary.rolled_back_steps = self.state.rolled_back_steps;
        summary.elapsed_s = self.state.elapsed_s;
        Ok(summary)
    }

    /// One optimiser step on `samples` at schedule factor `factor`: returns the step's record. A non-finite
    /// loss or gradient norm skips the step, an update that makes a weight non-finite is rolled back; either
    /// leaves the weights as they were and is counted ([`divergence`]).
    pub fn train_step(
        &mut self,
        samples: &[LoadedSample],
        factor: f64,
        maps: DepthFlowMaps,
    ) -> Result<StepRecord, TrainError> {
        let step = self.state.step;
        let started = Instant::now();
        let outcome = self.accumulate(samples, maps)?;
        // Every rank learns whether any rank's loss was not finite, so that all skip the step together.
        let measures = ranks::sum_measures(&self.group, outcome.as_ref().map(|o| o.measures.clone()))?;
        let mut record =
            StepRecord { step, lr_factor: factor, update: None, measures: None, failure: None, step_s: 0.0 };
        let failure = match (outcome, measures) {
            (Some(_), Some(measures)) if let Some(spike) = self.judge_spike(step, measures.loss) => {
                record.measures = Some(measures);
                Some(StepFailure::LossSpike(spike))
            }
            (Some(outcome), Some(mut measures)) => {
                let update = Instant::now();
                let master = self.replicas.master();
                let total = self.replicas.sum_on_master(outcome.grads);
                let total = sum_over_ranks(&self.group, &self.transport, &master.model, total)?;
                let stepped = self.replicas.step(self.replicas.share(total), factor);
                record.update = stepped.report().map(Into::into);
                measures.stage_seconds.insert("update".into(), update.elapsed().as_secs_f64());
                record.measures = Some(measures);
                StepFailure::of(&stepped)
            }
            _ => Some(StepFailure::NonFiniteLoss),
        };
        record.failure = failure.as_ref().map(FailureRecord::from);
        if let Some(average) = &mut self.average {
            average.fold(&self.replicas.master().model, step + 1);
        }
        record.step_s = started.elapsed().as_secs_f64();
        divergence::count_step(&mut self.state, step, failure.as_ref());
        self.last_failure = failure;
        self.state.step += 1;
        Ok(record)
    }

    /// Whether step `step`'s `loss` is a spike (`optim.skip_loss_spikes`), remembering it for the steps to come.
    /// The pose warm-up's losses (the camera term alone) are neither judged nor remembered: against them every
    /// full loss after the warm-up would be a spike.
    fn judge_spike(&mut self, step: u64, loss: f64) -> Option<Spike> {
        let section = self.config.optim.skip_loss_spikes?;
        if step < self.config.optim.pose_warmup_steps {
            return None;
        }
        let spike = spikes::judge(&self.state.recent_losses, loss, &section);
        spikes::remember(&mut self.state.recent_losses, loss, section.window);
        spike
    }

    /// [`dggt_run::RunError::Diverged`] once `optim.max_failed_steps_in_a_row` steps in a row have failed.
    fn check_divergence(&self) -> Result<(), TrainError> {
        let limit = DivergenceLimit {
            max_failed_in_a_row: self.config.optim.max_failed_steps_in_a_row,
            lr: self.config.optim.lr,
        };
        Ok(divergence::check(&self.state, self.last_failure.as_ref(), limit)?)
    }

    /// Loss and gradients of this process's samples of one step: every device takes its own consecutive
    /// `optim.accumulation` samples (on its own thread) and sums their gradients; `None` when a loss is not
    /// finite. Each loss is scaled by one over the step's samples on all ranks. The gradients come back per
    /// device, in device order, for [`Replicas::sum_on_master`].
    fn accumulate(&self, samples: &[LoadedSample], maps: DepthFlowMaps) -> Result<Option<StepOutcome>, TrainError> {
        let scale = 1.0 / (samples.len() * self.group.size()) as f64;
        let shares: Vec<&[LoadedSample]> = samples.chunks(samples.len().div_ceil(self.replicas.len())).collect();
        let results: Vec<Result<DeviceShare, TrainError>> = if shares.len() == 1 {
            vec![self.run_share(self.replicas.master(), shares[0], scale, maps)]
        } else {
            std::thread::scope(|scope| {
                let handles: Vec<_> = self
                    .replicas
                    .iter()
                    .zip(&shares)
                    .map(|(replica, share)| scope.spawn(move || self.run_share(replica, share, scale, maps)))
                    .collect();
                handles.into_iter().map(|h| h.join().expect("a training thread panicked")).collect()
            })
        };
        let mut outcome = StepOutcome::default();
        for share in results {
            let share = share?;
            let Some(grads) = share.grads else { return Ok(None) };
            outcome.grads.push(grads);
            for result in share.samples {
                outcome.add(&result, scale);
            }
        }
        Ok(Some(outcome))
    }

    /// Runs `share` on `replica`, summing its gradients on the replica's device.
    fn run_share(
        &self,
        replica: &Replica,
        share: &[LoadedSample],
        scale: f64,
        maps: DepthFlowMaps,
    ) -> Result<DeviceShare, TrainError> {
        let mut sum = GradientsAccumulator::<Dggt>::new();
        let mut samples = Vec::with_capacity(share.len());
        let mut finite = true;
        for sample in share {
            let (result, grads) = self.run_sample(&replica.model, sample, &replica.device, scale, maps)?;
            match grads {
                Some(grads) => sum.accumulate(&replica.model, grads),
                None => finite = false,
            }
            samples.push(result);
        }
        Ok(DeviceShare { grads: finite.then(|| sum.grads()), samples })
    }

    /// Loss and gradients of one sample; no gradients when the loss or the network's output is not finite.
    fn run_sample(
        &self,
        model: &Dggt,
        sample: &LoadedSample,
        device: &Device,
        scale: f64,
        maps: DepthFlowMaps,
    ) -> Result<(SampleResult, Option<GradientsParams>), TrainError> {
        let started = Instant::now();
        let preprocess = &self.config.data.preprocess;
        let batch = StepBatch::new(sample, &sample.scene, preprocess, maps, device)?;
        let prepared = Instant::now();
        let pose_warmup = sample.step < self.config.optim.pose_warmup_steps;
        let loss =
            if pose_warmup { self.objective.pose_loss(model, &batch) } else { self.objective.loss(model, &batch) };
        let loss = match loss {
            Err(error) if error.is_non_finite_output() => {
                tracing::warn!(step = sample.step, %error, "non-finite network output");
                return Ok((SampleResult::non_finite(), None));
            }
            other => other?,
        };
        let evaluated = Instant::now();
        let value = loss.terms.iter().fold(0.0, |sum, (term, v)| sum + v * term.weight(&self.config.loss));
        let grads = if value.is_finite() {
            let gradients = loss.total.mul_scalar(scale).backward();
            Some(GradientsParams::from_grads(gradients, model))
        } else {
            tracing::warn!(step = sample.step, ?loss.terms, "non-finite loss");
            None
        };
        let stages = [
            ("batch", (prepared - started).as_secs_f64()),
            ("forward_and_render", (evaluated - prepared).as_secs_f64()),
            ("backward", evaluated.elapsed().as_secs_f64()),
        ];
        let result = SampleResult {
            loss: value,
            terms: loss.terms,
            target_psnr: loss.target_psnr,
            kept: loss.counts.kept(),
            stages,
        };
        Ok((result, grads))
    }

    /// Writes a checkpoint of the master replica at the current step.
    fn save_checkpoint(&self) -> Result<PathBuf, TrainError> {
        let run = &self.config.run;
        let master = self.replicas.master();
        let settings = checkpoint::Settings {
            model: self.model_config.clone(),
            preprocess: self.config.data.preprocess,
            configured: ConfiguredSections::of(&self.config),
        };
        let weights = match self.average.as_ref().and_then(WeightAverage::average) {
            Some(average) => Weights::Averaged { trained: &master.model, average },
            None => Weights::Trained(&master.model),
        };
        checkpoint::save(
            &run.out_dir.join(run_folder::CHECKPOINTS),
            weights,
            &settings,
            &master.optimizer,
            &self.state,
            run.keep_checkpoints,
        )
    }
}

impl Trainer {
    /// Counts the load failures the samples carry; past `data.max_bad_samples` the run stops, after saving a
    /// checkpoint of the weights so far.
    fn count_bad_samples(&mut self, samples: &[LoadedSample]) -> Result<(), TrainError> {
        let failures: Vec<&String> = samples.iter().flat_map(|s| &s.failures).collect();
        self.state.bad_samples += ranks::sum_count(&self.group, failures.len() as u64)?;
        let limit = self.config.data.max_bad_samples;
        if self.state.bad_samples <= limit {
            return Ok(());
        }
        if self.group.is_writer() {
            self.save_checkpoint()?;
        }
        Err(TrainError::TooManyBadSamples {
            failed: self.state.bad_samples,
            limit,
            last: failures.last().map_or("-", |f| f.as_str()).to_string(),
        })
    }
}

/// The checkpoint a run continues from, if any, once its output folder is checked: a fresh run refuses a folder
/// holding another run ([`run_folder`]), a resume a configuration of another network or, unless `allowed`, of
/// other inputs ([`resume`]).
fn resume_point(config: &TrainConfig, start: Start, allowed: &AllowedChanges) -> Result<Option<PathBuf>, TrainError> {
    let dir = match start {
        Start::Fresh => {
            run_folder::ensure_no_run(&config.run.out_dir)?;
            return Ok(None);
        }
        Start::Resume => {
            dggt_run::checkpoint::latest(&config.run.out_dir.join(run_folder::CHECKPOINTS), Purpose::Resume)?
        }
    };
    if let Some(dir) = &dir {
        for change in resume::compare(dir, &checkpoint::read_model_config(dir)?, config, allowed)? {
            tracing::warn!("resuming with a changed setting: {change}");
        }
    }
    Ok(dir)
}

/// The average of the weights `optim.average` asks for, kept by the writing rank, continuing a checkpoint's
/// average `resumed` when there is one.
fn weight_average(config: &TrainConfig, resumed: Option<Dggt>, group: &ProcessGroup) -> Option<WeightAverage<Dggt>> {
    match (config.optim.average, resumed) {
        (Some(section), resumed) if group.is_writer() => Some(WeightAverage::new(section, resumed)),
        (None, Some(_)) => {
            tracing::warn!(
                "the checkpoint holds an average of the weights, and optim.average no longer asks for one: \
                 continuing from the trained weights without it"
            );
            None
        }
        _ => None,
    }
}

/// LPIPS-Alex for validation when `data.validation` names its weights.
fn validation_lpips(config: &TrainConfig, device: &Device) -> Result<Option<Lpips>, TrainError> {
    let v = &config.data.validation;
    match (&v.lpips_weights, &v.lpips_backbone) {
        (Some(linear), Some(backbone)) => Ok(Some(Lpips::load(LpipsKind::Alex, backbone, linear, device)?)),
        _ => Ok(None),
    }
}

/// Indexes the configured datasets (reusing `out_dir/scene-index.json` when still valid), excludes scenes too
/// short for the sampler's window, and picks the validation scenes.
fn index_datasets(config: &TrainConfig) -> Result<(DatasetSampling, Vec<IndexedScene>), TrainError> {
    let specs = config.data.dataset_specs(&config.sampler.cameras);
    fs::create_dir_all(&config.run.out_dir)
        .map_err(|source| TrainError::Io { path: config.run.out_dir.clone(), source })?;
    let cache = config.run.out_dir.join(SCENE_INDEX);
    // Drawn only when stderr is a terminal.
    let template = "indexing scenes {elapsed_precise} [{bar:30}] {pos}/{len} ({per_sec}, {eta})";
    let bar = styled_bar(template, Visibility::Shown, None);
    let show = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let mut index = DatasetIndex::load_or_build(&specs, config.run.seed, &cache, &show)?;
    bar.finish_and_clear();
    check_single_scene(config, &index)?;
    index.exclude_shorter_than(config.sampler.window);
    if !index.excluded.is_empty() {
        tracing::warn!(excluded = index.excluded.len(), indexed = index.scenes.len(), "scenes excluded (see the log)");
    }
    let mix = SceneMix::new(&index, config.run.seed)?;
    let mut validation_scenes: Vec<IndexedScene> = index.split(Split::Validation).cloned().collect();
    if validation_scenes.is_empty() {
        validation_scenes.extend(index.split(Split::Train).next().cloned());
    }
    let needed = config.data.validation.inputs.iter().chain(&config.data.validation.targets).max().map(|f| f + 1);
    if let Some(scene) = validation_scenes.iter().find(|s| needed.is_some_and(|n| s.frame_count() < n)) {
        return Err(TrainError::ValidationFrame {
            frame: needed.unwrap_or(0) - 1,
            frame_count: scene.frame_count(),
            scene: scene.root.clone(),
        });
    }
    tracing::info!(
        training = index.split(Split::Train).count(),
        validation = validation_scenes.len(),
        excluded = index.excluded.len(),
        "scenes indexed"
    );
    let sampling =
        DatasetSampling { index: Arc::new(index), mix, sampler: config.sampler.clone(), seed: config.run.seed };
    Ok((sampling, validation_scenes))
}

/// A run on one scene (`data.scene`) uses all of the frames `data.frames` names: a range reaching outside the
/// scene, or a scene that cannot be indexed, is an error rather than a quietly smaller run. (A dataset's
/// `frames` is clipped to each of its scenes, as documented.)
fn check_single_scene(config: &TrainConfig, index: &DatasetIndex) -> Result<(), TrainError> {
    if !config.data.datasets.is_empty() {
        return Ok(());
    }
    if let Some(excluded) = index.excluded.first() {
        return Err(TrainError::SceneExcluded { scene: excluded.root.clone(), reason: excluded.reason.clone() });
    }
    let (Some([start, end]), Some(scene)) = (config.data.frames, index.scenes.first()) else { return Ok(()) };
    // The index clips the range to the scene's frames: each bound it moved lies outside them.
    let (first, last) = (scene.frames.start, scene.frames.end);
    let valid = match (start < first, end > last) {
        (false, false) => return Ok(()),
        (true, false) => format!("a start of at least {first}"),
        (false, true) => format!("an end of at most {last}"),
        (true, true) => format!("a range within [{first}, {last})"),
    };
    Err(TrainError::Setting {
        setting: "data.frames",
        detail: format!("[{start}, {end}) reaches outside the frames of {}: give {valid}", scene.root.display()),
    })
}

/// What one sample of a step measured.
struct SampleResult {
    loss: f64,
    terms: std::collections::BTreeMap<LossTerm, f64>,
    target_psnr: f64,
    kept: usize,
    stages: [(&'static str, f64); 3],
}

impl SampleResult {
    /// A sample whose network outputs were not finite: no gradients, so the step is skipped.
    fn non_finite() -> Self {
        Self {
            loss: f64::NAN,
            terms: Default::default(),
            target_psnr: f64::NAN,
            kept: 0,
            stages: [("batch", 0.0), ("forward_and_render", 0.0), ("backward", 0.0)],
        }
    }
}

/// One device's part of a step: its summed gradients (`None` when a sample was not finite) and its samples.
struct DeviceShare {
    grads: Option<GradientsParams>,
    samples: Vec<SampleResult>,
}

/// A step's gradients per device and its metrics averaged over the samples.
#[derive(Default)]
struct StepOutcome {
    grads: Vec<GradientsParams>,
    measures: StepMeasures,
}

impl StepOutcome {
    /// Adds one sample's metrics, weighted by `scale` (one over the samples of the step).
    fn add(&mut self, result: &SampleResult, scale: f64) {
        let measures = &mut self.measures;
        measures.loss += result.loss * scale;
        measures.target_psnr += result.target_psnr * scale;
        measures.gaussians_kept += result.kept;
        for (name, value) in &result.terms {
            *measures.terms.entry(name.name().to_string()).or_default() += value * scale;
        }
        for (name, value) in result.stages {
            *measures.stage_seconds.entry(name.to_string()).or_default() += value;
        }
    }
}

fn next_sample(stream: &mut Prefetcher<LoadedSample>) -> Result<LoadedSample, TrainError> {
    match stream.next() {
        Some(sample) => Ok(sample?),
        None => Err(TrainError::StreamEnded),
    }
}
