//! The run loop: samples streamed, one step after another at the scheduled rate, each step's record logged and
//! shown; load failures counted, divergence and the time limit checked; checkpoints saved and validation passes
//! run when they fall due; and the summary of how the run ended.

use std::fs;
use std::path::PathBuf;
use std::time::Instant;

use dggt_data::{LoadedSample, LoaderOptions, Prefetcher, dataset_stream};
use dggt_objective::DepthFlowMaps;
use dggt_run::divergence::{self, CheckpointDue, DivergenceLimit};
use dggt_run::metrics::{MetricsLog, RecordKind};
use dggt_run::progress::{Visibility, progress_bar};
use dggt_run::{failpoint, run_folder};

use super::setup::Trainer;
use crate::error::TrainError;
use crate::ranks;
use crate::records::LoggedStep;
use crate::validate::Validation;
use crate::watch::{RunWatcher, Unwatched};

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

impl Trainer {
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
        let data = &self.config.data;
        let options_loader = LoaderOptions {
            workers: data.workers.max(1),
            capacity: 2 * data.workers.max(1),
            decoded_cache_bytes: data.decoded_cache_mb << 20,
        };
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
        let maps = if loss.rendered_depth > 0.0 {
            DepthFlowMaps::InputsAndTargets
        } else if loss.depth > 0.0 || loss.flow > 0.0 || loss.learnt_flow > 0.0 {
            DepthFlowMaps::Inputs
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

    /// [`dggt_run::RunError::Diverged`] once `optim.max_failed_steps_in_a_row` steps in a row have failed.
    fn check_divergence(&self) -> Result<(), TrainError> {
        let limit = DivergenceLimit {
            max_failed_in_a_row: self.config.optim.max_failed_steps_in_a_row,
            lr: self.config.optim.lr,
        };
        Ok(divergence::check(&self.state, self.last_failure.as_ref(), limit)?)
    }

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

fn next_sample(stream: &mut Prefetcher<LoadedSample>) -> Result<LoadedSample, TrainError> {
    match stream.next() {
        Some(sample) => Ok(sample?),
        None => Err(TrainError::StreamEnded),
    }
}
