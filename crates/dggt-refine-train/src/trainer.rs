//! The refiner's training loop on a training run's machinery (`dggt-run`): its AdamW ([`Optimizer`]) with clipping, its
//! schedule ([`WarmupCosine`]), its checkpoint folders (`checkpoints/step-NNNNNNNN/` with `model.bpk`,
//! `optimizer.bpk` and `state.json`, the `latest` pointer written last) and its run state.
//!
//! A step refines `run.batch` training pairs drawn from `(seed, step)` at timestep 199 from a latent sampled
//! with the seed `seed ^ step`, and steps AdamW on the loss; everything is a function of the seed, the step
//! and the saved weights and moments, so a resumed run continues exactly. Validation refines the held-out
//! pairs from the posterior mean and reports their PSNR against the targets (and that of the unrefined
//! renders). A step that fails (a non-finite loss or gradient, or an update rolled back) is counted, and too
//! many in a row stop the run; a checkpoint falling due meanwhile waits for a step that trains
//! ([`dggt_run::divergence`]). Records go to `out_dir/metrics.jsonl` ([`dggt_run::metrics`]), one JSON object a
//! line with its `kind` and `step`, as the DGGT trainer writes them (a resumed run first drops the records it
//! is about to write again).

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::optim::GradientsParams;
use burn::tensor::Device;
use dggt_metrics::psnr;
use dggt_model::host::host_f32;
use dggt_model::safetensors_file::SafetensorsFile;
use dggt_refine::{Latent, Prompt};
use dggt_run::checkpoint::{Purpose, RunState, Weights, latest, load_model, optimizer_file, read_state, save_folder};
use dggt_run::compute_pool::on_pool_worker;
use dggt_run::divergence::{self, CheckpointDue, CheckpointGate, DivergenceLimit, StepFailure};
use dggt_run::metrics::{MetricsLog, RecordKind};
use dggt_run::progress::{Visibility, progress_bar};
use dggt_run::schedule::WarmupCosine;
use dggt_run::{Optimizer, Start, run_folder};

use crate::config::{PairsSection, RefineTrainConfig};
use crate::difix_checkpoint::{to_difix_checkpoint, write_difix_checkpoint};
use crate::error::RefineTrainError;
use crate::fresh::fresh_checkpoint;
use crate::loss::RefineLoss;
use crate::model::TrainableRefiner;
use crate::pair_files::PairFiles;
use crate::pairs::{Image, Pair, PairSet, PairSource, batch, batch_pairs, read_images, step_indices, synthetic_pairs};
use crate::records::{StepRecord, Validation};
use crate::watch::{RefineWatcher, RefinedPicture, Unwatched};

pub struct RefineTrainer {
    config: RefineTrainConfig,
    model: TrainableRefiner,
    optimizer: Optimizer,
    loss: RefineLoss,
    pairs: PairSet,
    state: RunState,
    /// The training device (with autodiff).
    device: Device,
    /// The same device without autodiff (validation).
    plain_device: Device,
    /// Why the last step failed, when it did.
    last_failure: Option<StepFailure>,
    /// Holds back checkpoints while steps fail.
    checkpoint_gate: CheckpointGate,
}

impl RefineTrainer {
    /// Checks `config`, then loads the refiner, the losses and the pairs to train on `device` (given without autodiff, which the
    /// trainer adds), resuming from the newest checkpoint under `run.out_dir` when `start` says so and there is
    /// one.
    pub fn new(config: RefineTrainConfig, plain_device: Device, start: Start) -> Result<Self, RefineTrainError> {
        config.validate()?;
        if start == Start::Fresh {
            run_folder::ensure_no_run(&config.run.out_dir)?;
        }
        let device = plain_device.clone().autodiff();
        let tokens = prompt_tokens(&config)?;
        let model = load_model_of(&config, &tokens, &device)?;
        let loss = RefineLoss::load(&config.loss, &device)?;
        let pairs = load_pairs(&config.pairs)?;
        let optimizer = Optimizer::ungrouped(&config.optim.section());
        let state = RunState::starting(config.run.seed, config.run.batch as u64);
        let mut trainer = Self {
            config,
            model,
            optimizer,
            loss,
            pairs,
            state,
            device,
            plain_device,
            last_failure: None,
            checkpoint_gate: CheckpointGate::default(),
        };
        if start == Start::Resume
            && let Some(dir) = latest(&trainer.checkpoints(), Purpose::Resume)?
        {
            trainer.resume_from(&dir)?;
        }
        Ok(trainer)
    }

    pub fn model(&self) -> &TrainableRefiner {
        &self.model
    }

    pub fn state(&self) -> &RunState {
        &self.state
    }

    pub fn pairs(&self) -> &PairSet {
        &self.pairs
    }

    fn checkpoints(&self) -> PathBuf {
        self.config.run.out_dir.join(run_folder::CHECKPOINTS)
    }

    fn schedule(&self) -> WarmupCosine {
        let optim = self.config.optim.section();
        WarmupCosine {
            peak: optim.lr,
            warmup: optim.warmup_steps,
            total: self.config.run.steps,
            min_ratio: optim.min_lr_ratio,
        }
    }

    /// One optimiser step. A non-finite loss or gradient leaves the weights untouched (counted as skipped), an
    /// update that makes a weight non-finite is rolled back (counted as such).
    pub fn step(&mut self) -> Result<StepRecord, RefineTrainError> {
        let step = self.state.step;
        let indices = step_indices(self.state.seed, step, self.config.run.batch, self.pairs.train_len());
        let limit = self.config.pairs.max_bad_pairs;
        let chosen = indices
            .iter()
            .map(|&i| readable_pair(&self.pairs, i, &mut self.state, limit))
            .collect::<Result<Vec<_>, _>>()?;
        let (render, target, reference) =
            batch_pairs(&chosen.iter().map(AsRef::as_ref).collect::<Vec<_>>(), &self.device)?;
        let refined = self.model.refine(render, reference, Latent::Sampled { seed: self.state.seed ^ step })?;
        let value = self.loss.compute(refined, target, step)?;
        let loss: f32 = value.total.clone().into_scalar();
        let mut record = StepRecord {
            step,
            loss: loss.into(),
            l2: value.l2,
            lpips: value.lpips,
            gram: value.gram,
            grad_norm: None,
            failure: None,
        };
        let mut failure = Some(StepFailure::NonFiniteLoss);
        if loss.is_finite() {
            let grads = GradientsParams::from_grads(value.total.backward(), &self.model.weights);
            let factor = self.schedule().factor(step);
            let (weights, outcome) = self.optimizer.step(self.model.weights.clone(), grads, factor);
            self.model.weights = weights;
            record.grad_norm = outcome.report().map(|r| r.grad_norm);
            failure = StepFailure::of(&outcome);
        }
        record.failure = failure.as_ref().map(StepFailure::describe);
        divergence::count_step(&mut self.state, step, failure.as_ref());
        self.last_failure = failure;
        self.state.step += 1;
        Ok(record)
    }

    /// [`dggt_run::RunError::Diverged`] once `optim.max_failed_steps_in_a_row` steps in a row have failed.
    fn check_divergence(&self) -> Result<(), RefineTrainError> {
        let optim = &self.config.optim;
        let limit = DivergenceLimit { max_failed_in_a_row: optim.max_failed_steps_in_a_row, lr: optim.lr };
        Ok(divergence::check(&self.state, self.last_failure.as_ref(), limit)?)
    }

    /// Trains to `run.steps` with a progress bar (drawn as `progress` says), validating and checkpointing on the
    /// configured cadence and at the end. Returns the last validation.
    pub fn run(&mut self, progress: Visibility) -> Result<Validation, RefineTrainError> {
        self.run_watched(progress, &mut Unwatched)
    }

    /// [`RefineTrainer::run`], showing `watcher` every step and validation pass.
    pub fn run_watched(
        &mut self,
        progress: Visibility,
        watcher: &mut dyn RefineWatcher,
    ) -> Result<Validation, RefineTrainError> {
        let run = self.config.run.clone();
        let bar = progress_bar(progress, self.state.step, run.steps);
        let started = Instant::now();
        let elapsed_before = self.state.elapsed_s;
        let mut last = None;
        let mut metrics = MetricsLog::continuing_at(&run.out_dir.join(run_folder::METRICS), self.state.step)?;
        while self.state.step < run.steps {
            let record = match on_pool_worker(|| self.step()) {
                Ok(record) => record,
                Err(error) => {
                    // The weights and state of the last completed step are kept for `--resume`.
                    if let Err(save) = self.save_checkpoint() {
                        tracing::error!("no checkpoint saved after the failure: {save}");
                    }
                    return Err(error);
                }
            };
            bar.set_message(format!("loss {:.4}", record.loss));
            bar.inc(1);
            metrics.append(RecordKind::Train, &record)?;
            watcher.step(&record);
            // No checkpoint then: the weights are those the last one holds, and a new one could prune it.
            self.check_divergence()?;
            let step = self.state.step;
            self.state.elapsed_s = elapsed_before + started.elapsed().as_secs_f64();
            if run.validate_every > 0 && step.is_multiple_of(run.validate_every) && step < run.steps {
                last = Some(self.validate_and_record(&mut metrics, watcher)?);
            }
            let due =
                if step.is_multiple_of(run.checkpoint_every) { CheckpointDue::Periodic } else { CheckpointDue::No };
            if step < run.steps && self.checkpoint_gate.write_now(&self.state, due) {
                self.save_checkpoint()?;
            }
        }
        bar.finish_and_clear();
        if last.is_none_or(|v: Validation| v.step != self.state.step) {
            last = Some(self.validate_and_record(&mut metrics, watcher)?);
        }
        self.save_checkpoint()?;
        Ok(last.expect("validated above"))
    }

    fn validate_and_record(
        &self,
        metrics: &mut MetricsLog,
        watcher: &mut dyn RefineWatcher,
    ) -> Result<Validation, RefineTrainError> {
        let validation = self
            .validate_watched(watcher)
            .map_err(|source| RefineTrainError::Validation { step: self.state.step, source: Box::new(source) })?;
        tracing::info!(
            step = validation.step,
            refined_psnr = validation.refined_psnr,
            render_psnr = validation.render_psnr,
            "held-out pairs"
        );
        metrics.append(RecordKind::Validation, &validation)?;
        Ok(validation)
    }

    /// PSNR of the held-out pairs, refined from the posterior mean, and of the renders as they are.
    pub fn validate(&self) -> Result<Validation, RefineTrainError> {
        self.validate_watched(&mut Unwatched)
    }

    /// [`RefineTrainer::validate`], shown to `watcher` with the first held-out pairs it asks for.
    pub fn validate_watched(&self, watcher: &mut dyn RefineWatcher) -> Result<Validation, RefineTrainError> {
        let wanted = watcher.pictures_wanted();
        let mut pictures = Vec::with_capacity(wanted);
        let (mut refined_sum, mut render_sum) = (0.0, 0.0);
        let model = self.model.valid();
        let mut scored = 0;
        for index in 0..self.pairs.held_out_len() {
            let pair = match self.pairs.held_out(index) {
                Ok(pair) => pair,
                Err(error) => {
                    tracing::warn!("held-out pair {index} left out of the validation: {error}");
                    continue;
                }
            };
            scored += 1;
            let (render, _, reference) = batch_pairs(&[&pair], &self.plain_device)?;
            let refined = model.refine(render, reference, Latent::PosteriorMean)?;
            let refined = host_f32(refined, "validation: refined image")?;
            refined_sum += psnr(&refined, &pair.target.values)?;
            render_sum += psnr(&pair.render.values, &pair.target.values)?;
            if pictures.len() < wanted {
                let (height, width) = (pair.target.height, pair.target.width);
                let refined = Image { height, width, values: refined };
                let Pair { render, target, .. } = pair.into_owned();
                pictures.push(RefinedPicture { index, render, refined, target });
            }
        }
        if scored == 0 && self.pairs.held_out_len() > 0 {
            return Err(RefineTrainError::NoHeldOutPairReadable);
        }
        let count = scored.max(1) as f64;
        let validation =
            Validation { step: self.state.step, refined_psnr: refined_sum / count, render_psnr: render_sum / count };
        watcher.validation(&validation, &pictures);
        Ok(validation)
    }

    /// Writes the trained refiner to `path` as a Difix checkpoint for the refiner's loader
    /// ([`crate::difix_checkpoint`]).
    pub fn write_difix_checkpoint(&self, path: &Path) -> Result<(), RefineTrainError> {
        write_difix_checkpoint(&to_difix_checkpoint(&self.model)?, path)
    }

    /// The run's configuration.
    pub fn config(&self) -> &RefineTrainConfig {
        &self.config
    }

    /// The refined image of `image` (attending to `reference` when given) from the posterior mean, on the host.
    pub fn refine_host(&self, image: &Image, reference: Option<&Image>) -> Result<Vec<f32>, RefineTrainError> {
        let reference = reference.map(|r| batch(&[r], &self.plain_device)).transpose()?;
        let image = batch(&[image], &self.plain_device)?;
        let refined = self.model.valid().refine(image, reference, Latent::PosteriorMean)?;
        Ok(host_f32(refined, "refined image")?)
    }

    /// Writes `checkpoints/step-NNNNNNNN/` and points `latest` at it; keeps the newest `run.keep_checkpoints`.
    pub fn save_checkpoint(&self) -> Result<PathBuf, RefineTrainError> {
        let keep = self.config.run.keep_checkpoints;
        Ok(save_folder(
            &self.checkpoints(),
            Weights::Trained(&self.model.weights),
            &self.optimizer,
            &self.state,
            keep,
            &[],
        )?)
    }

    /// Continues from the checkpoint folder `dir`: weights, AdamW moments and run state.
    fn resume_from(&mut self, dir: &Path) -> Result<(), RefineTrainError> {
        let loaded = load_model(dir, self.model.weights.clone())?;
        self.model = self.model.clone().with_loaded_weights(loaded);
        self.optimizer.load(&optimizer_file(dir), &self.device)?;
        self.state = read_state(dir)?;
        tracing::info!(checkpoint = %dir.display(), step = self.state.step, "resumed");
        Ok(())
    }
}

/// Training pair `index`, or when it cannot be read the next readable one (wrapping, so a persistent failure
/// is replaced the same way in a resumed run); each failure is warned about, naming the file, and counted in
/// `state.bad_samples`, and past `limit` of them the run stops.
fn readable_pair<'a>(
    pairs: &'a PairSet,
    index: usize,
    state: &mut RunState,
    limit: u64,
) -> Result<Cow<'a, Pair>, RefineTrainError> {
    let count = pairs.train_len();
    for position in (index..count).chain(0..index) {
        let error = match pairs.train(position) {
            Ok(pair) => return Ok(pair),
            Err(error) => error,
        };
        state.bad_samples += 1;
        tracing::warn!("training pair {position} replaced by the next one: {error}");
        if state.bad_samples > limit {
            return Err(RefineTrainError::TooManyBadPairs {
                failed: state.bad_samples,
                limit,
                last: error.to_string(),
            });
        }
    }
    Err(RefineTrainError::NoTrainingPairReadable { count })
}

/// The refiner to train: the configured checkpoint over the base, or a fresh start from the base.
fn load_model_of(
    config: &RefineTrainConfig,
    tokens: &[i64],
    device: &Device,
) -> Result<TrainableRefiner, RefineTrainError> {
    let model = &config.model;
    match &model.checkpoint {
        Some(path) => TrainableRefiner::load(&model.base_dir, path, tokens, device),
        None => {
            let checkpoint = fresh_checkpoint(&model.base_dir, model.lora_rank, config.run.seed)?;
            TrainableRefiner::from_checkpoint(&model.base_dir, checkpoint, &model.base_dir, tokens, device)
        }
    }
}

/// The configured pairs: rendered ones from their file or folder of shards, or synthetic ones from clean images.
fn load_pairs(section: &PairsSection) -> Result<PairSet, RefineTrainError> {
    match (&section.rendered, &section.images) {
        (Some(source), _) => PairSet::new(PairSource::Files(PairFiles::open(source)?), section.held_out),
        (None, Some(images)) => {
            synthetic_pairs(&read_images(images, &section.tensors)?, section.variants, section.held_out)
        }
        (None, None) => {
            Err(RefineTrainError::Setting { setting: "pairs", detail: "neither `rendered` nor `images` given".into() })
        }
    }
}

/// The prompt's token ids from the configuration: its text (by default Difix's prompt) through the base
/// folder's tokenizer, or its ids.
fn prompt_tokens(config: &RefineTrainConfig) -> Result<Vec<i64>, RefineTrainError> {
    let model = &config.model;
    let Some(path) = &model.prompt_tokens_file else {
        let prompt = if model.prompt_tokens.is_empty() {
            model.prompt.clone().map_or_else(Prompt::default, Prompt::Text)
        } else {
            Prompt::Tokens(model.prompt_tokens.clone())
        };
        return Ok(prompt.token_ids(&model.base_dir)?);
    };
    let invalid = |detail: String| RefineTrainError::PromptTokens { path: path.clone(), detail };
    let mut file = SafetensorsFile::open(path)?;
    let dtype = &file.entry("input_ids").map_err(|_| invalid("no tensor 'input_ids'".into()))?.dtype;
    if dtype != "I64" {
        return Err(invalid(format!("'input_ids' is {dtype}, expected int64")));
    }
    let ids = file.read_data("input_ids")?;
    ids.try_into_vec::<i64>().map_err(|e| invalid(format!("'input_ids' not readable as int64: {e:?}")))
}
