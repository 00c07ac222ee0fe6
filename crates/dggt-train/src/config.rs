//! The training configuration, read from TOML. Every section has defaults; unknown keys are errors, so a typo
//! never silently falls back to a default. Paths are relative to the configuration file.

use std::path::{Path, PathBuf};

use dggt_data::{Preprocess, SamplerConfig};
use dggt_geom::PixelConvention;
use dggt_scene::{AssemblySettings, DynamicBlend};
use serde::{Deserialize, Serialize};

use crate::error::TrainError;

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
}

/// Which network, and where its starting weights come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelSection {
    /// `tiny`, `vggt_1b` or `dggt` (the released architecture).
    pub preset: String,
    /// Starting weights with the release's key names (`.pt`, `.pth`, `.safetensors`): a VGGT-1B checkpoint
    /// (the Gaussian heads then start fresh) or the DGGT release. `None` starts from random weights.
    pub init_checkpoint: Option<PathBuf>,
    /// Turn on the Gaussian head's colour skip (`GaussianHeadConfig::color_skip`; off in the release).
    pub color_skip: bool,
    /// Where Gaussian means are unprojected (`GaussianHeadConfig::unproject_at`): `integer` (the release's
    /// convention, required by its weights) or `centred` (pixel centres, for training from scratch).
    pub unproject_at: PixelConvention,
    /// Sky Gaussians per side (`SkyConfig::resolution`, `resolution^2` in all) instead of the preset's; only
    /// for a sky model that starts fresh, since a checkpoint's sky buffers fix their count.
    pub sky_resolution: Option<usize>,
    /// Add the motion head (`ModelConfig::motion_head`; not in the release's weights, so it starts fresh from
    /// predicting zero): dynamic Gaussians are moved to each target time by their predicted velocity.
    pub motion_head: bool,
    /// Give the Gaussian head velocity channels (`GaussianHeadConfig::velocity`; not in the release's weights,
    /// so they start at zero): the motion of the dynamic Gaussians for three output channels instead of a head.
    pub gaussian_velocity: bool,
    /// Give every DPT head a convolution of the input pixels (`DptConfig::pixel_skip`; not in the release's
    /// weights, so only for heads that start fresh).
    pub pixel_skip: bool,
}

impl Default for ModelSection {
    fn default() -> Self {
        Self {
            preset: "tiny".into(),
            init_checkpoint: None,
            color_skip: false,
            unproject_at: PixelConvention::Integer,
            sky_resolution: None,
            motion_head: false,
            gaussian_velocity: false,
            pixel_skip: false,
        }
    }
}

/// The training scene and how its views are prepared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DataSection {
    /// A scene export or KITTI odometry sequence.
    pub scene: PathBuf,
    /// Log frames `[start, end)` to use; all when absent.
    pub frames: Option<[usize; 2]>,
    pub preprocess: Preprocess,
    /// Validation: target frames rendered between fixed input frames and scored. The sampler may also draw
    /// these frames in training (an overfit check); validate on another scene to measure generalisation.
    pub validation: ValidationSection,
    /// Decoding threads.
    pub workers: usize,
}

impl Default for DataSection {
    fn default() -> Self {
        Self {
            scene: PathBuf::from("data-fixtures/synth-s0"),
            frames: None,
            preprocess: Preprocess::default(),
            validation: ValidationSection::default(),
            workers: 2,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ValidationSection {
    /// Input frames of the validation pass (positions in the scene's frame list).
    pub inputs: Vec<usize>,
    /// Target frames rendered and scored (PSNR, SSIM); interpolated between the inputs.
    pub targets: Vec<usize>,
}

impl Default for ValidationSection {
    fn default() -> Self {
        Self { inputs: vec![0, 5, 10, 15], targets: vec![2, 7, 12] }
    }
}

/// Where the rendered Gaussians are placed and from which cameras they are rendered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSection {
    /// `predicted`: the camera head's poses (world = first input camera), as at inference. `ground_truth`:
    /// the export's poses expressed in the first input camera's frame (training from scratch, before the
    /// camera head is useful).
    pub cameras: CameraSource,
    /// Whether the rendering losses reach the depth through the Gaussian means (the release detaches them).
    pub means_gradient: MeansGradientSetting,
    /// Also re-render the input views (the release trains on those only; the paper adds 2N targets).
    pub render_inputs: bool,
    /// Render the sky model as the background.
    pub sky: bool,
    /// Camera-space depth beyond which Gaussians are not drawn (gsplat's far plane). A finite bound keeps
    /// depths that nothing supervises from running away (a scene without sky masks pushes its background out).
    pub far_plane: f64,
    /// Which input views' dynamic Gaussians a target shows: `nearest` (the release) or `cross_fade` (the two
    /// bracketing views, opacities weighted by time).
    pub dynamic_blend: DynamicBlend,
    /// The rasteriser's low-pass variance in pixels² (`eps2d`; 0.3 in the release, whose weights assume it).
    /// A model trained from scratch renders sharper with a smaller one.
    pub eps2d: f64,
}

impl RenderSection {
    /// How targets are assembled and rasterised under these settings (training, and the reconstructions and
    /// evaluations of a model trained with them).
    pub fn assembly(&self) -> AssemblySettings {
        AssemblySettings {
            far_plane: self.far_plane as f32,
            dynamic_blend: self.dynamic_blend,
            eps2d: self.eps2d as f32,
            ..AssemblySettings::default()
        }
    }
}

impl Default for RenderSection {
    fn default() -> Self {
        Self {
            cameras: CameraSource::Predicted,
            means_gradient: MeansGradientSetting::Detached,
            render_inputs: true,
            sky: true,
            far_plane: 1e10,
            dynamic_blend: DynamicBlend::Nearest,
            eps2d: 0.3,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraSource {
    Predicted,
    GroundTruth,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeansGradientSetting {
    Detached,
    Through,
}

/// Weight of every loss term (0 turns a term off). Defaults follow the paper's terms with the release's
/// weights: L2 + LPIPS 0.05 + opacity BCE + dynamic BCE 0.05 + lifespan 0.01.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossWeights {
    /// Mean squared error of the rendered colours.
    pub rgb_l2: f64,
    /// LPIPS (needs `lpips_weights`).
    pub lpips: f64,
    /// `alex` or `vgg`.
    pub lpips_net: String,
    /// The lpips package's linear layers (`alex.pth`/`vgg.pth` or safetensors).
    pub lpips_weights: Option<PathBuf>,
    /// The torchvision backbone (`features.N.*`), `.pth` or safetensors.
    pub lpips_backbone: Option<PathBuf>,
    /// Rendered alpha against 1 - sky mask (binary cross-entropy).
    pub opacity_bce: f64,
    /// Dynamic logits against the dynamic masks of the inputs (binary cross-entropy from logits).
    pub dynamic_bce: f64,
    /// Mean `1 / lifespan` over the static Gaussians.
    pub lifespan_l1: f64,
    /// Gram matrices of VGG-16 features (needs `gram_backbone`).
    pub gram: f64,
    pub gram_backbone: Option<PathBuf>,
    /// Supervision from the export's ground truth, for training from scratch: L1 on the pose encodings of
    /// every camera-head iteration against the poses relative to the first input.
    pub camera: f64,
    /// L1 on log depth against the export's depth maps.
    pub depth: f64,
    /// L1 of the predicted velocities against the export's scene flow (`depth_flows_4`), both in the input
    /// camera's axes and world units per log frame, the mean over moving cells plus the mean over still ones;
    /// needs `model.motion_head` or `model.gaussian_velocity`.
    pub flow: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            rgb_l2: 1.0,
            lpips: 0.05,
            lpips_net: "alex".into(),
            lpips_weights: None,
            lpips_backbone: None,
            opacity_bce: 0.1,
            dynamic_bce: 0.05,
            lifespan_l1: 0.01,
            gram: 0.0,
            gram_backbone: None,
            camera: 0.0,
            depth: 0.0,
            flow: 0.0,
        }
    }
}

/// AdamW, learning-rate schedule, clipping, accumulation, parameter groups and frozen modules.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimSection {
    /// Peak learning rate of every trainable parameter outside `groups`.
    pub lr: f64,
    /// Top-level modules (`sky_model`, `gs_head`, ...) with their own peak learning rate.
    pub groups: std::collections::BTreeMap<String, f64>,
    /// Top-level modules that are not trained (the release freezes `aggregator`, `camera_head`, `depth_head`).
    pub frozen: Vec<String>,
    pub weight_decay: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
    /// Linear warm-up from 0 over this many steps, then cosine decay to `min_lr_ratio · lr`.
    pub warmup_steps: u64,
    pub min_lr_ratio: f64,
    /// Clip the global gradient norm to this value; `None` disables clipping.
    pub clip_grad_norm: Option<f64>,
    /// Samples whose gradients are summed (averaged) per optimiser step.
    pub accumulation: usize,
    /// The first steps train the camera loss alone (`loss.camera`, against the export's poses): the aggregator
    /// and camera head run, no dense head and no render, so each costs a fraction of a full step. For training
    /// from scratch, where the camera head otherwise learns per-frame positions last. Counted in `run.steps`
    /// and the schedule.
    pub pose_warmup_steps: u64,
}

impl Default for OptimSection {
    fn default() -> Self {
        Self {
            lr: 4e-5,
            groups: [("sky_model".to_string(), 1e-4)].into_iter().collect(),
            frozen: Vec::new(),
            weight_decay: 1e-4,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            warmup_steps: 1000,
            min_lr_ratio: 0.0,
            clip_grad_norm: Some(1.0),
            accumulation: 1,
            pose_warmup_steps: 0,
        }
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
        config.validate().map_err(|detail| TrainError::Config { path: path.into(), detail })?;
        Ok(config)
    }

    fn resolve_paths(&mut self, base: &Path) {
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        resolve(&mut self.data.scene);
        resolve(&mut self.run.out_dir);
        for path in [
            &mut self.model.init_checkpoint,
            &mut self.loss.lpips_weights,
            &mut self.loss.lpips_backbone,
            &mut self.loss.gram_backbone,
        ]
        .into_iter()
        .flatten()
        {
            resolve(path);
        }
    }

    /// Checks values that no type can: positive counts, known names, weights that need files have them.
    pub fn validate(&self) -> Result<(), String> {
        let o = &self.optim;
        if !(o.lr > 0.0 && o.lr.is_finite()) || o.groups.values().any(|lr| !(*lr >= 0.0 && lr.is_finite())) {
            return Err("optim: learning rates must be finite, lr > 0, group rates >= 0".into());
        }
        if o.accumulation == 0 || self.run.steps == 0 || self.run.checkpoint_every == 0 {
            return Err("optim.accumulation, run.steps and run.checkpoint_every must be at least 1".into());
        }
        if !(0.0..=1.0).contains(&o.min_lr_ratio) {
            return Err(format!("optim.min_lr_ratio must lie in [0, 1], got {}", o.min_lr_ratio));
        }
        if let Some(clip) = o.clip_grad_norm
            && !(clip > 0.0)
        {
            return Err(format!("optim.clip_grad_norm must be positive, got {clip}"));
        }
        if self.model.sky_resolution == Some(0) {
            return Err("model.sky_resolution must be at least 1".into());
        }
        if self.model.motion_head && self.model.gaussian_velocity {
            return Err("model.motion_head and model.gaussian_velocity both predict the velocities: choose one".into());
        }
        if o.pose_warmup_steps > 0 && !(self.loss.camera > 0.0) {
            return Err("optim.pose_warmup_steps trains the camera loss alone: it needs loss.camera > 0".into());
        }
        let modules = [
            "aggregator",
            "camera_head",
            "depth_head",
            "point_head",
            "gs_head",
            "instance_head",
            "semantic_head",
            "sky_model",
            "motion_head",
        ];
        for name in o.frozen.iter().chain(o.groups.keys()) {
            if !modules.contains(&name.as_str()) {
                return Err(format!("optim: unknown module `{name}` (known: {modules:?})"));
            }
        }
        let l = &self.loss;
        let weights =
            [l.rgb_l2, l.lpips, l.opacity_bce, l.dynamic_bce, l.lifespan_l1, l.gram, l.camera, l.depth, l.flow];
        if weights.iter().any(|w| !(*w >= 0.0 && w.is_finite())) {
            return Err("loss: weights must be finite and >= 0".into());
        }
        if l.lpips > 0.0 && (l.lpips_weights.is_none() || l.lpips_backbone.is_none()) {
            return Err(
                "loss.lpips > 0 needs loss.lpips_weights and loss.lpips_backbone (or set loss.lpips = 0)".into()
            );
        }
        if !["alex", "vgg"].contains(&l.lpips_net.as_str()) {
            return Err(format!("loss.lpips_net must be `alex` or `vgg`, got `{}`", l.lpips_net));
        }
        if l.flow > 0.0 && !(self.model.motion_head || self.model.gaussian_velocity) {
            return Err("loss.flow supervises predicted velocities: it needs model.motion_head or \
                        model.gaussian_velocity"
                .into());
        }
        if l.gram > 0.0 && l.gram_backbone.is_none() {
            return Err("loss.gram > 0 needs loss.gram_backbone".into());
        }
        if !(self.render.eps2d.is_finite() && self.render.eps2d > 0.0) {
            // Zero leaves flat Gaussians seen edge-on with a singular footprint.
            return Err(format!("render.eps2d must be a positive, finite variance, got {}", self.render.eps2d));
        }
        if !(self.render.far_plane > 0.01) {
            return Err(format!("render.far_plane must exceed the near plane 0.01, got {}", self.render.far_plane));
        }
        if self.run.devices.is_empty() {
            return Err("run.devices must name at least one device".into());
        }
        if self.data.validation.inputs.is_empty() != self.data.validation.targets.is_empty() {
            return Err("data.validation: give both inputs and targets, or neither".into());
        }
        Ok(())
    }
}
