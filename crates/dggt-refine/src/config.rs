//! The sizes of the refiner's three networks and its noise schedule, read from a diffusers model folder
//! (`vae/config.json`, `unet/config.json`, `text_encoder/config.json`, `scheduler/scheduler_config.json`).
//! Only the settings the sd-turbo family uses are accepted; any other value of a setting that changes the
//! computation is an error naming the file and the setting.

use std::path::Path;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::error::RefineError;

/// `AutoencoderKL`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VaeConfig {
    pub in_channels: usize,
    pub out_channels: usize,
    pub latent_channels: usize,
    pub block_out_channels: Vec<usize>,
    pub layers_per_block: usize,
    pub norm_num_groups: usize,
    pub scaling_factor: f32,
    #[serde(default = "yes")]
    pub mid_block_add_attention: bool,
    #[serde(default = "yes")]
    pub use_quant_conv: bool,
    #[serde(default = "yes")]
    pub use_post_quant_conv: bool,
}

/// `UNet2DConditionModel` in the SD 2.1 layout.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct UnetConfig {
    pub in_channels: usize,
    pub out_channels: usize,
    pub block_out_channels: Vec<usize>,
    pub layers_per_block: usize,
    pub down_block_types: Vec<String>,
    pub up_block_types: Vec<String>,
    /// Heads per level (diffusers' historical name for it).
    pub attention_head_dim: HeadsPerLevel,
    pub num_attention_heads: Option<HeadsPerLevel>,
    pub cross_attention_dim: usize,
    pub norm_num_groups: usize,
    pub norm_eps: f64,
    pub flip_sin_to_cos: bool,
    pub freq_shift: f64,
    pub use_linear_projection: bool,
    #[serde(default)]
    pub upcast_attention: bool,
    #[serde(default = "one")]
    pub transformer_layers_per_block: usize,
}

/// A head count for every level, or one for all.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum HeadsPerLevel {
    All(usize),
    Each(Vec<usize>),
}

impl HeadsPerLevel {
    pub fn at(&self, level: usize) -> usize {
        match self {
            Self::All(heads) => *heads,
            Self::Each(heads) => heads[level.min(heads.len() - 1)],
        }
    }
}

/// transformers' `CLIPTextModel`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TextEncoderConfig {
    pub vocab_size: usize,
    pub hidden_size: usize,
    pub intermediate_size: usize,
    pub num_hidden_layers: usize,
    pub num_attention_heads: usize,
    pub max_position_embeddings: usize,
    pub hidden_act: String,
    pub layer_norm_eps: f64,
}

/// The DDPM noise schedule (`scaled_linear` betas).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SchedulerConfig {
    pub beta_start: f64,
    pub beta_end: f64,
    pub beta_schedule: String,
    pub num_train_timesteps: usize,
    pub prediction_type: String,
}

fn yes() -> bool {
    true
}

fn one() -> usize {
    1
}

/// A JSON configuration file.
pub fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, RefineError> {
    let text = std::fs::read_to_string(path).map_err(|e| RefineError::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| RefineError::file(path, format!("invalid configuration: {e}")))
}

/// An error unless `supported`: the setting `what` of `path` has a value this crate does not implement.
pub fn require(supported: bool, path: &Path, what: impl FnOnce() -> String) -> Result<(), RefineError> {
    if supported { Ok(()) } else { Err(RefineError::Config { path: path.display().to_string(), message: what() }) }
}
