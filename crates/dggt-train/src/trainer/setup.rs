//! A run set up: its configuration checked, its output folder checked and its datasets indexed, the network
//! and optimiser built fresh or resumed from a checkpoint on every device, with LPIPS for validation and the
//! weights' average; and what the built trainer exposes.

use std::path::PathBuf;

use burn::tensor::Device;
use dggt_collective::ProcessGroup;
use dggt_data::{DatasetIndex, DatasetSampling, DecodedViews, IndexedScene, LoadedSample};
use dggt_infer::{StartingWeights, fresh_model};
use dggt_losses::{Lpips, LpipsKind};
use dggt_model::{Dggt, ModelConfig};
use dggt_objective::Objective;
use dggt_run::average::WeightAverage;
use dggt_run::checkpoint::{Purpose, RunState, optimizer_file};
use dggt_run::divergence::{CheckpointGate, StepFailure};
use dggt_run::schedule::WarmupCosine;
use dggt_run::{Start, run_folder};

use super::datasets::index_datasets;
use crate::checkpoint;
use crate::config::TrainConfig;
use crate::error::TrainError;
use crate::modules::{freeze, grouped_optimizer};
use crate::rank_gradients::GradientTransport;
use crate::ranks;
use crate::replicas::Replicas;
use crate::resume::{self, AllowedChanges};

pub struct Trainer {
    pub(super) config: TrainConfig,
    pub(super) model_config: ModelConfig,
    /// The indexed scenes and how each sample draws from them.
    pub(super) sampling: DatasetSampling,
    /// Scored by [`Trainer::validate`]: the held-out scenes, or the first training scene.
    pub(super) validation_scenes: Vec<IndexedScene>,
    pub(super) objective: Objective,
    /// The network and optimiser on every training device (with autodiff); the first is the master.
    pub(super) replicas: Replicas,
    /// The first device without autodiff (validation).
    pub(super) plain_device: Device,
    /// LPIPS-Alex for validation, when configured.
    pub(super) validation_lpips: Option<Lpips>,
    pub(super) state: RunState,
    /// Why the last step failed, when it did.
    pub(super) last_failure: Option<StepFailure>,
    /// Holds back checkpoints while steps fail.
    pub(super) checkpoint_gate: CheckpointGate,
    /// The average of the master's weights (`optim.average`; rank 0 alone keeps it).
    pub(super) average: Option<WeightAverage<Dggt>>,
    /// The processes of the run (this one alone, or the ranks of an MPI job).
    pub(super) group: ProcessGroup,
    /// How the ranks' gradients travel (host buffers, or NCCL on CUDA devices).
    pub(super) transport: GradientTransport,
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
    // The public constructors' style (`Trainer::new(config, devices, start)`): a run is handed its devices.
    #[allow(clippy::needless_pass_by_value)]
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

    /// The sample drawn for sample index `index` (`step · samples_per_step + j`), decoded.
    pub fn sample(&self, index: u64) -> Result<LoadedSample, TrainError> {
        Ok(self.sampling.load(&self.config.data.preprocess, index, &DecodedViews::none())?)
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
