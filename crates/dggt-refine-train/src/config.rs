//! The configuration of a refiner training run (`dggt refine-train --config FILE.toml`).
//!
//! Defaults are the Difix paper's and its release's: loss `L2 + LPIPS + 0.5 Gram`, AdamW at a constant
//! learning rate of 2e-5 with betas (0.9, 0.999), weight decay 1e-2, epsilon 1e-8 and the gradient norm
//! clipped to 1, timestep 199 ([`dggt_refine::TIMESTEP`]). Relative paths are resolved against the file's
//! folder.

use std::path::{Path, PathBuf};

/// The LPIPS network of `loss.lpips_kind`.
pub use dggt_losses::LpipsKind;
use dggt_run::divergence;
use dggt_run::optim_config::DEFAULT_MAX_FAILED_STEPS_IN_A_ROW;
use dggt_run::{OptimSection, ViewerSection};
use serde::{Deserialize, Serialize};

use crate::error::RefineTrainError;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RefineTrainConfig {
    pub model: ModelSection,
    pub pairs: PairsSection,
    pub loss: LossSection,
    #[serde(default)]
    pub optim: OptimSettings,
    #[serde(default)]
    pub run: RunSection,
    /// What a live view of the run shows and how often (`dggt refine-train --rerun`); ignored without one.
    #[serde(default)]
    pub viewer: ViewerSection,
}

/// The refiner trained from: a diffusers folder and a Difix checkpoint over it (its LoRA factors are the
/// starting point), and its prompt: text through the folder's tokenizer (by default "remove degradation"), or
/// token ids (listed, or in a file) for a folder without one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSection {
    pub base_dir: PathBuf,
    /// `model_difix.pkl` (torch) or a trained refiner this crate wrote ([`crate::difix_checkpoint`],
    /// `.safetensors`); without one, training starts from the base model with fresh skip convolutions and LoRA
    /// ([`crate::fresh`]).
    #[serde(default)]
    pub checkpoint: Option<PathBuf>,
    /// The LoRA rank of a fresh start (Difix's is 4).
    #[serde(default = "default_rank")]
    pub lora_rank: usize,
    /// The prompt as text, tokenised by `base_dir/tokenizer/`.
    #[serde(default)]
    pub prompt: Option<String>,
    /// The prompt's token ids, or `prompt_tokens_file`: a safetensors file with an integer `input_ids`.
    #[serde(default)]
    pub prompt_tokens: Vec<i64>,
    #[serde(default)]
    pub prompt_tokens_file: Option<PathBuf>,
}

/// Where the pairs come from: a file of pairs rendered by a reconstruction (`rendered`,
/// [`crate::render_pairs`]), or clean images degraded synthetically (`images` with `tensors`,
/// [`crate::pairs`]). Exactly one of the two.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairsSection {
    /// A pairs file, or a folder of pair files (`dggt refine-pairs --shards`).
    #[serde(default)]
    pub rendered: Option<PathBuf>,
    /// A safetensors file of clean images: its tensors `tensors` (`[3, H, W]` or `[N, 3, H, W]` float32 in
    /// [0, 1]); each image gives `variants` pairs with synthetic degradations.
    #[serde(default)]
    pub images: Option<PathBuf>,
    #[serde(default)]
    pub tensors: Vec<String>,
    #[serde(default = "default_variants")]
    pub variants: usize,
    /// The last this many pairs are held out for validation.
    #[serde(default = "default_held_out")]
    pub held_out: usize,
    /// How many drawn pairs may fail to read before the run stops (after saving a checkpoint); each is
    /// replaced by the next readable training pair, with a warning naming its file.
    #[serde(default = "default_max_bad_pairs")]
    pub max_bad_pairs: u64,
}

/// Loss weights and the perceptual networks' weight files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossSection {
    #[serde(default = "one")]
    pub l2: f64,
    #[serde(default = "one")]
    pub lpips: f64,
    #[serde(default = "default_gram")]
    pub gram: f64,
    /// The first step the Gram term counts at (0: from the start, the paper's; the Difix release's training
    /// script starts it after 2000 steps).
    #[serde(default)]
    pub gram_start_step: u64,
    /// The LPIPS backbone (the Difix release uses `vgg`).
    #[serde(default = "default_lpips_kind")]
    pub lpips_kind: LpipsKind,
    /// A full LPIPS state dict (backbone and linear layers).
    pub lpips_weights: PathBuf,
    /// VGG-16 `features` weights (torchvision names) of the Gram loss.
    pub gram_vgg: PathBuf,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunSection {
    pub steps: u64,
    pub seed: u64,
    /// Pairs per optimiser step.
    pub batch: usize,
    pub out_dir: PathBuf,
    pub checkpoint_every: u64,
    pub keep_checkpoints: usize,
    /// Validate every this many steps (and at the end); 0: only at the end.
    pub validate_every: u64,
}

impl Default for RunSection {
    fn default() -> Self {
        Self {
            steps: 1000,
            seed: 0,
            batch: 1,
            out_dir: PathBuf::from("runs/refine"),
            checkpoint_every: 200,
            keep_checkpoints: 2,
            validate_every: 100,
        }
    }
}

/// AdamW as Difix trains, each setting defaulting to the paper's and its release's: rate 2e-5 held constant
/// after `warmup_steps` (0), betas (0.9, 0.999), weight decay 1e-2, epsilon 1e-8, gradient norm clipped to 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OptimSettings {
    pub lr: f64,
    pub weight_decay: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
    pub warmup_steps: u64,
    pub clip_grad_norm: Option<f64>,
    /// Steps in a row that may fail (non-finite loss or gradient, or an update rolled back) before the run
    /// stops as diverged.
    pub max_failed_steps_in_a_row: u64,
}

impl Default for OptimSettings {
    fn default() -> Self {
        Self {
            lr: 2e-5,
            weight_decay: 1e-2,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
            warmup_steps: 0,
            clip_grad_norm: Some(1.0),
            max_failed_steps_in_a_row: DEFAULT_MAX_FAILED_STEPS_IN_A_ROW,
        }
    }
}

impl OptimSettings {
    /// The trainer's optimiser section: no groups, nothing frozen by name, the rate constant after warm-up.
    pub fn section(&self) -> OptimSection {
        OptimSection {
            lr: self.lr,
            groups: Default::default(),
            frozen: Vec::new(),
            weight_decay: self.weight_decay,
            beta1: self.beta1,
            beta2: self.beta2,
            epsilon: self.epsilon,
            warmup_steps: self.warmup_steps,
            min_lr_ratio: 1.0,
            clip_grad_norm: self.clip_grad_norm,
            accumulation: 1,
            pose_warmup_steps: 0,
            max_failed_steps_in_a_row: self.max_failed_steps_in_a_row,
            average: None,
            skip_loss_spikes: None,
        }
    }
}

fn one() -> f64 {
    1.0
}

/// The paper's weight of the Gram loss.
fn default_gram() -> f64 {
    0.5
}

fn default_lpips_kind() -> LpipsKind {
    LpipsKind::Vgg
}

fn default_rank() -> usize {
    4
}

fn default_variants() -> usize {
    4
}

fn default_held_out() -> usize {
    1
}

fn default_max_bad_pairs() -> u64 {
    100
}

impl RefineTrainConfig {
    /// Reads a TOML file, resolves its relative paths and checks it.
    pub fn load(path: &Path) -> Result<Self, RefineTrainError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| RefineTrainError::Io { path: path.into(), source })?;
        let mut config: Self =
            toml::from_str(&text).map_err(|e| RefineTrainError::Config { path: path.into(), detail: e.to_string() })?;
        config.resolve_paths(path.parent().unwrap_or(Path::new(".")));
        config.validate().map_err(|e| RefineTrainError::Config { path: path.into(), detail: e.to_string() })?;
        Ok(config)
    }

    fn resolve_paths(&mut self, base: &Path) {
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        resolve(&mut self.model.base_dir);
        for file in [&mut self.model.checkpoint, &mut self.model.prompt_tokens_file].into_iter().flatten() {
            resolve(file);
        }
        for file in [&mut self.pairs.images, &mut self.pairs.rendered].into_iter().flatten() {
            resolve(file);
        }
        resolve(&mut self.loss.lpips_weights);
        resolve(&mut self.loss.gram_vgg);
        resolve(&mut self.run.out_dir);
    }

    /// Settings out of range or contradicting each other.
    pub fn validate(&self) -> Result<(), RefineTrainError> {
        let check = |ok: bool, setting: &'static str, detail: &str| {
            if ok { Ok(()) } else { Err(RefineTrainError::Setting { setting, detail: detail.into() }) }
        };
        let prompts = [
            self.model.prompt.is_some(),
            !self.model.prompt_tokens.is_empty(),
            self.model.prompt_tokens_file.is_some(),
        ];
        check(
            prompts.iter().filter(|&&given| given).count() <= 1,
            "model.prompt",
            "give at most one of prompt, prompt_tokens and prompt_tokens_file",
        )?;
        check(
            self.pairs.images.is_some() != self.pairs.rendered.is_some(),
            "pairs",
            "give exactly one of `rendered` (a pairs file) and `images` (synthetic pairs)",
        )?;
        check(self.pairs.images.is_none() || !self.pairs.tensors.is_empty(), "pairs.tensors", "name the images")?;
        check(self.model.lora_rank > 0, "model.lora_rank", "must be at least 1")?;
        check(self.pairs.variants > 0, "pairs.variants", "must be at least 1")?;
        check(self.run.batch > 0, "run.batch", "must be at least 1")?;
        check(self.run.checkpoint_every > 0, "run.checkpoint_every", "must be at least 1")?;
        check(self.optim.lr > 0.0, "optim.lr", "must be positive")?;
        check(self.optim.beta1 < 1.0 && self.optim.beta2 < 1.0, "optim.beta1/beta2", "must be below 1")?;
        divergence::validate_limit("optim.max_failed_steps_in_a_row", self.optim.max_failed_steps_in_a_row)?;
        self.viewer.check().map_err(|detail| RefineTrainError::Setting { setting: "viewer", detail })?;
        let weights = [self.loss.l2, self.loss.lpips, self.loss.gram];
        check(weights.iter().all(|w| w.is_finite() && *w >= 0.0), "loss", "weights must be finite and >= 0")
    }
}
