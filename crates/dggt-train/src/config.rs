//! The training configuration, read from TOML. Every section has defaults; unknown keys are errors, so a typo
//! never silently falls back to a default. Paths are relative to the configuration file.

use std::path::{Path, PathBuf};

use dggt_data::{DatasetSpec, LoaderOptions, Preprocess, SamplerConfig};
use dggt_flow_head::FlowHeadShape;
pub use dggt_infer::{CameraSource, ModelSection, RenderSection};
use dggt_objective::LossTerm;
pub use dggt_objective::LossWeights;
use dggt_run::divergence;
pub use dggt_run::{OptimSection, ViewerSection};
use dggt_scene::FlowHeadMismatch;
use serde::{Deserialize, Serialize};

use crate::error::TrainError;
use crate::modules::MODULES;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    pub model: ModelSection,
    pub data: DataSection,
    pub sampler: SamplerConfig,
    pub render: RenderSection,
    pub loss: LossWeights,
    pub optim: OptimSection,
    pub run: RunSection,
    /// What a live view of the run shows and how often (`dggt train --rerun`); ignored without one.
    pub viewer: ViewerSection,
}

/// The training scenes and how their views are prepared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DataSection {
    /// One scene export or KITTI odometry sequence: the run's only dataset when `datasets` is empty.
    pub scene: PathBuf,
    /// Log frames `[start, end)` of `scene` to use; all when absent.
    pub frames: Option<[usize; 2]>,
    /// Datasets of scene folders (`[[data.datasets]]`), mixed by weight, some scenes held out for validation.
    pub datasets: Vec<DatasetSpec>,
    pub preprocess: Preprocess,
    /// Validation: target frames rendered between fixed input frames and scored, on every held-out scene (or,
    /// when none is held out, on the first training scene: an overfit check).
    pub validation: ValidationSection,
    /// Decoding threads.
    pub workers: usize,
    /// MiB of decoded, preprocessed images and masks kept between steps, so that a view drawn again is not
    /// decoded again (0: decode every time).
    pub decoded_cache_mb: usize,
    /// Samples that may fail to load (each replaced by another scene's, with a warning) before the run stops.
    pub max_bad_samples: u64,
}

impl DataSection {
    /// The run's datasets: `datasets`, or `scene` as a dataset of one. `cameras` (the sampler's) fill in
    /// datasets that name none.
    pub fn dataset_specs(&self, cameras: &[usize]) -> Vec<DatasetSpec> {
        let mut specs = if self.datasets.is_empty() {
            vec![DatasetSpec { root: Some(self.scene.clone()), frames: self.frames, ..DatasetSpec::default() }]
        } else {
            self.datasets.clone()
        };
        for spec in specs.iter_mut().filter(|spec| spec.cameras.is_empty()) {
            spec.cameras = cameras.to_vec();
        }
        specs
    }
}

impl Default for DataSection {
    fn default() -> Self {
        Self {
            scene: PathBuf::from("data-fixtures/synth-s0"),
            frames: None,
            preprocess: Preprocess::default(),
            datasets: Vec::new(),
            validation: ValidationSection::default(),
            workers: 2,
            decoded_cache_mb: LoaderOptions::DEFAULT_DECODED_CACHE_BYTES >> 20,
            max_bad_samples: 100,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ValidationSection {
    /// Input frames of the validation pass (positions in the scene's frame list).
    pub inputs: Vec<usize>,
    /// Target frames rendered and scored (PSNR, SSIM, LPIPS, D-RMSE); interpolated between the inputs.
    pub targets: Vec<usize>,
    /// LPIPS-Alex's linear layers (the lpips package's `alex.pth`, or safetensors with its names); with
    /// `lpips_backbone`, validation also scores LPIPS.
    pub lpips_weights: Option<PathBuf>,
    /// AlexNet `features` weights (torchvision or lpips names; may be the same file as `lpips_weights`).
    pub lpips_backbone: Option<PathBuf>,
}

impl Default for ValidationSection {
    fn default() -> Self {
        Self { inputs: vec![0, 5, 10, 15], targets: vec![2, 7, 12], lpips_weights: None, lpips_backbone: None }
    }
}

/// The run: length, seed, output, cadence, devices.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunSection {
    /// Optimiser steps.
    pub steps: u64,
    pub seed: u64,
    pub out_dir: PathBuf,
    /// Write a checkpoint every this many steps (and at the end).
    pub checkpoint_every: u64,
    /// Checkpoints kept on disk (oldest removed first).
    pub keep_checkpoints: usize,
    /// Validate every this many steps (and at the end); 0 only at the end. Each pass writes its renders to
    /// `out_dir/validation/step-N/`.
    pub validate_every: u64,
    /// Stop when this many seconds have passed (after the step that crosses it), checkpointing first.
    pub time_limit_s: Option<f64>,
    /// Devices of data-parallel training (`cpu`, `ndarray`, `wgpu:N`, `cuda:N`); each takes a share of the
    /// accumulated samples and the gradients are summed before the step.
    pub devices: Vec<String>,
}

impl Default for RunSection {
    fn default() -> Self {
        Self {
            steps: 1000,
            seed: 0,
            out_dir: PathBuf::from("runs/train"),
            checkpoint_every: 200,
            keep_checkpoints: 2,
            validate_every: 100,
            time_limit_s: None,
            devices: vec!["cpu".into()],
        }
    }
}

impl TrainConfig {
    /// The run made unattended, for training driven from code (tests, examples): outputs under `out_dir`, no
    /// validation, no time limit, a single checkpoint at the end.
    pub fn unattended(mut self, out_dir: &Path) -> Self {
        self.run.out_dir = out_dir.to_path_buf();
        self.run.validate_every = 0;
        self.run.checkpoint_every = u64::MAX;
        self.run.time_limit_s = None;
        self.data.validation.inputs.clear();
        self.data.validation.targets.clear();
        self
    }

    /// Reads a TOML file; relative paths in it are resolved against its folder.
    pub fn load(path: &Path) -> Result<Self, TrainError> {
        let text = std::fs::read_to_string(path).map_err(|source| TrainError::Io { path: path.into(), source })?;
        let mut config: Self =
            toml::from_str(&text).map_err(|e| TrainError::Config { path: path.into(), detail: e.to_string() })?;
        let base = path.parent().unwrap_or(Path::new("."));
        config.resolve_paths(base);
        config.validate().map_err(|e| TrainError::Config { path: path.into(), detail: e.to_string() })?;
        Ok(config)
    }

    fn resolve_paths(&mut self, base: &Path) {
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        resolve(&mut self.data.scene);
        for spec in &mut self.data.datasets {
            spec.resolve_paths(base);
        }
        resolve(&mut self.run.out_dir);
        for path in [
            &mut self.model.init_checkpoint,
            &mut self.loss.lpips_weights,
            &mut self.loss.lpips_backbone,
            &mut self.loss.gram_backbone,
            &mut self.data.validation.lpips_weights,
            &mut self.data.validation.lpips_backbone,
        ]
        .into_iter()
        .flatten()
        {
            resolve(path);
        }
    }

    /// Checks values that no type can: positive counts, known names, weights that need files have them.
    pub fn validate(&self) -> Result<(), TrainError> {
        self.validate_optim()?;
        self.validate_model()?;
        self.validate_loss()?;
        self.validate_render_and_run()
    }

    fn validate_optim(&self) -> Result<(), TrainError> {
        let o = &self.optim;
        if !(o.lr > 0.0 && o.lr.is_finite()) || o.groups.values().any(|lr| !(*lr >= 0.0 && lr.is_finite())) {
            return Err(setting("optim", "learning rates must be finite, lr > 0, group rates >= 0"));
        }
        for (name, value) in [
            ("optim.accumulation", o.accumulation as u64),
            ("run.steps", self.run.steps),
            ("run.checkpoint_every", self.run.checkpoint_every),
        ] {
            if value == 0 {
                return Err(setting(name, "must be at least 1, got 0"));
            }
        }
        number("optim.min_lr_ratio", o.min_lr_ratio, "[0, 1]", |v| (0.0..=1.0).contains(&v))?;
        number("optim.weight_decay", o.weight_decay, "[0, inf)", |v| v >= 0.0)?;
        number("optim.beta1", o.beta1, "[0, 1)", |v| (0.0..1.0).contains(&v))?;
        number("optim.beta2", o.beta2, "[0, 1)", |v| (0.0..1.0).contains(&v))?;
        number("optim.epsilon", o.epsilon, "(0, inf)", |v| v > 0.0)?;
        if let Some(clip) = o.clip_grad_norm {
            number("optim.clip_grad_norm", clip, "(0, inf)", |v| v > 0.0)?;
        }
        divergence::validate_limit("optim.max_failed_steps_in_a_row", o.max_failed_steps_in_a_row)?;
        if let Some(average) = o.average {
            number("optim.average.decay", average.decay, "(0, 1)", |v| v > 0.0 && v < 1.0)?;
            if average.start_step >= self.run.steps {
                return Err(setting(
                    "optim.average.start_step",
                    format!("{} never starts in a run of run.steps = {}", average.start_step, self.run.steps),
                ));
            }
        }
        if let Some(spikes) = o.skip_loss_spikes {
            number("optim.skip_loss_spikes.factor", spikes.factor, "(1, inf)", |v| v > 1.0 && v.is_finite())?;
            if spikes.window < 3 {
                return Err(setting(
                    "optim.skip_loss_spikes.window",
                    format!("must be at least 3, got {}", spikes.window),
                ));
            }
        }
        if o.pose_warmup_steps > 0 && !(self.loss.camera > 0.0) {
            return Err(setting("optim.pose_warmup_steps", "trains the camera loss alone: it needs loss.camera > 0"));
        }
        for name in o.frozen.iter().chain(o.groups.keys()) {
            if !MODULES.contains(&name.as_str()) {
                return Err(setting("optim", format!("unknown module `{name}` (known: {MODULES:?})")));
            }
        }
        Ok(())
    }

    fn validate_model(&self) -> Result<(), TrainError> {
        if self.model.sky_resolution == Some(0) {
            return Err(setting("model.sky_resolution", "must be at least 1"));
        }
        if self.model.motion_head && self.model.gaussian_velocity {
            return Err(setting(
                "model.motion_head and model.gaussian_velocity",
                "both predict the velocities: choose one",
            ));
        }
        if !self.model.flow_head && self.model.flow != FlowHeadShape::default() {
            return Err(setting("model.flow", "shapes the flow head: it needs model.flow_head = true"));
        }
        match self.render.dynamic_motion.flow_head_mismatch(self.model.flow_head) {
            Some(FlowHeadMismatch::LearntWithoutHead) => Err(setting(
                "render.dynamic_motion",
                "\"learnt\" moves the dynamic Gaussians along the flow head's flow: it needs model.flow_head = true",
            )),
            Some(FlowHeadMismatch::HeadWithoutLearnt) => Err(setting(
                "model.flow_head",
                "the flow head learns from renders along its flow: it needs render.dynamic_motion = \"learnt\"",
            )),
            None => Ok(()),
        }
    }

    fn validate_loss(&self) -> Result<(), TrainError> {
        let l = &self.loss;
        if let Some(term) = LossTerm::ALL.into_iter().find(|t| !(t.weight(l) >= 0.0 && t.weight(l).is_finite())) {
            return Err(setting("loss", format!("weights must be finite and >= 0 (loss.{term} is not)")));
        }
        if l.lpips > 0.0 && (l.lpips_weights.is_none() || l.lpips_backbone.is_none()) {
            return Err(setting(
                "loss.lpips",
                "> 0 needs loss.lpips_weights and loss.lpips_backbone (or set loss.lpips = 0)",
            ));
        }
        let v = &self.data.validation;
        if v.lpips_weights.is_some() != v.lpips_backbone.is_some() {
            return Err(setting(
                "data.validation.lpips_weights",
                "LPIPS needs both data.validation.lpips_weights and data.validation.lpips_backbone",
            ));
        }
        if l.flow > 0.0 && !(self.model.motion_head || self.model.gaussian_velocity) {
            return Err(setting(
                "loss.flow",
                "supervises predicted velocities: it needs model.motion_head or model.gaussian_velocity",
            ));
        }
        if l.learnt_flow > 0.0 && !self.model.flow_head {
            return Err(setting(
                "loss.learnt_flow",
                "supervises the flow head's learnt flow: it needs model.flow_head",
            ));
        }
        if l.gram > 0.0 && l.gram_backbone.is_none() {
            return Err(setting("loss.gram", "> 0 needs loss.gram_backbone"));
        }
        Ok(())
    }

    fn validate_render_and_run(&self) -> Result<(), TrainError> {
        // Zero leaves flat Gaussians seen edge-on with a singular footprint.
        number("render.eps2d", self.render.eps2d, "(0, inf)", |v| v > 0.0)?;
        number("render.far_plane", self.render.far_plane, "(0.01, inf), beyond the near plane", |v| v > 0.01)?;
        if self.run.devices.is_empty() {
            return Err(setting("run.devices", "must name at least one device"));
        }
        self.viewer.check().map_err(|detail| setting("viewer", detail))?;
        if self.run.keep_checkpoints == 0 {
            return Err(setting("run.keep_checkpoints", "must be at least 1, got 0"));
        }
        if let Some(limit) = self.run.time_limit_s {
            number("run.time_limit_s", limit, "(0, inf)", |v| v > 0.0)?;
        }
        self.validate_data()
    }

    fn validate_data(&self) -> Result<(), TrainError> {
        let data = &self.data;
        if let Some([start, end]) = data.frames
            && start >= end
        {
            return Err(setting(
                "data.frames",
                format!("[{start}, {end}) is empty: give [start, end) with start < end"),
            ));
        }
        data.preprocess.validate().map_err(|e| setting("data.preprocess", e.to_string()))?;
        self.sampler.check_counts().map_err(|e| setting("sampler", e.to_string()))?;
        for spec in &data.datasets {
            spec.validate().map_err(|e| setting("data.datasets", e.to_string()))?;
        }
        if data.validation.inputs.is_empty() != data.validation.targets.is_empty() {
            return Err(setting("data.validation", "give both inputs and targets, or neither"));
        }
        Ok(())
    }
}

fn setting(setting: &'static str, detail: impl Into<String>) -> TrainError {
    TrainError::Setting { setting, detail: detail.into() }
}

/// Refuses the value of `name` unless it is finite and `valid`; `range` says which values are (`[0, 1)`).
fn number(name: &'static str, value: f64, range: &str, valid: impl Fn(f64) -> bool) -> Result<(), TrainError> {
    if value.is_finite() && valid(value) {
        return Ok(());
    }
    Err(setting(name, format!("must lie in {range}, got {value}")))
}
