//! A refiner with made-up weights at a given configuration ([`Weights::random`]): the run time and memory
//! of the full-size refiner (sd-turbo's sizes, [`RefinerConfigs::sd_turbo`]) without its weights at hand.
//! Its images mean nothing.

use std::collections::HashMap;
use std::path::Path;

use burn::tensor::Device;
use serde_json::json;

use crate::config::{SchedulerConfig, TextEncoderConfig, UnetConfig, VaeConfig, read_json};
use crate::error::RefineError;
use crate::refiner::{Refiner, TIMESTEP, check_vae};
use crate::scheduler::{SingleStep, alphas_cumprod};
use crate::text_encoder::TextEncoder;
use crate::unet::Unet;
use crate::vae::Vae;
use crate::weights::{NamedTensors, Weights, write_safetensors};

/// The four configurations of a refiner's model folder.
#[derive(Debug, Clone)]
pub struct RefinerConfigs {
    pub vae: VaeConfig,
    pub unet: UnetConfig,
    pub text_encoder: TextEncoderConfig,
    pub scheduler: SchedulerConfig,
}

impl RefinerConfigs {
    /// The configurations of a diffusers model folder.
    pub fn read(model_dir: &Path) -> Result<Self, RefineError> {
        Ok(Self {
            vae: read_json(&model_dir.join("vae/config.json"))?,
            unet: read_json(&model_dir.join("unet/config.json"))?,
            text_encoder: read_json(&model_dir.join("text_encoder/config.json"))?,
            scheduler: read_json(&model_dir.join("scheduler/scheduler_config.json"))?,
        })
    }

    /// sd-turbo's sizes (SD 2.1's networks): UNet widths 320/640/1280/1280 with 5/10/20/20 heads of 64 channels
    /// and cross-attention width 1024; VAE widths 128/256/512/512; the OpenCLIP ViT-H text encoder (width 1024,
    /// 23 layers, 16 heads, vocabulary 49408); the DDPM schedule of the refiner.
    pub fn sd_turbo() -> Self {
        Self {
            vae: parse(json!({
                "in_channels": 3, "out_channels": 3, "latent_channels": 4,
                "block_out_channels": [128, 256, 512, 512], "layers_per_block": 2, "norm_num_groups": 32,
                "scaling_factor": 0.18215
            })),
            unet: parse(json!({
                "in_channels": 4, "out_channels": 4, "block_out_channels": [320, 640, 1280, 1280],
                "layers_per_block": 2,
                "down_block_types": ["CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"],
                "up_block_types": ["UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"],
                "attention_head_dim": [5, 10, 20, 20], "cross_attention_dim": 1024, "norm_num_groups": 32,
                "norm_eps": 1e-5, "flip_sin_to_cos": true, "freq_shift": 0, "use_linear_projection": true
            })),
            text_encoder: parse(json!({
                "vocab_size": 49408, "hidden_size": 1024, "intermediate_size": 4096, "num_hidden_layers": 23,
                "num_attention_heads": 16, "max_position_embeddings": 77, "hidden_act": "gelu",
                "layer_norm_eps": 1e-5
            })),
            scheduler: parse(json!({
                "beta_start": 0.00085, "beta_end": 0.012, "beta_schedule": "scaled_linear",
                "num_train_timesteps": 1000, "prediction_type": "epsilon"
            })),
        }
    }
}

/// A built-in configuration.
fn parse<T: serde::de::DeserializeOwned>(value: serde_json::Value) -> T {
    serde_json::from_value(value).expect("a valid built-in configuration")
}

impl Refiner {
    /// A refiner of the sizes `configs` give with made-up weights (see [`Weights::random`]), its prompt 77
    /// made-up token ids. `origin` names where the configurations came from, for error messages.
    pub fn random(configs: &RefinerConfigs, origin: &Path, device: &Device) -> Result<Self, RefineError> {
        check_vae(&configs.vae, origin)?;
        let vae = Vae::load(&mut Weights::random(device), &configs.vae)?;
        let unet = Unet::load(&mut Weights::random(device), &configs.unet, origin)?;
        let encoder = TextEncoder::load(&mut Weights::random(device), &configs.text_encoder, origin)?;
        let vocab = configs.text_encoder.vocab_size as i64;
        let tokens: Vec<i64> =
            (0..configs.text_encoder.max_position_embeddings as i64).map(|i| i * 7 % vocab).collect();
        let prompt_embeds = encoder.forward(&tokens)?;
        drop(encoder);
        let step = SingleStep::new(&alphas_cumprod(&configs.scheduler, origin)?, TIMESTEP)?;
        Ok(Self { vae, unet, prompt_embeds, step, scaling_factor: configs.vae.scaling_factor })
    }
}

/// Writes a model folder of `configs`' sizes in the diffusers layout with made-up weights (as
/// [`Refiner::random`] makes them, f32): `vae/`, `unet/` and `text_encoder/` with their configurations and
/// safetensors, and `scheduler/`. No tokenizer: prompts for it are token ids. What loading at full size is
/// measured on (`dggt bench refiner --write-model`, then `--model DIR --load`). One network's host copy is held
/// at a time.
pub fn write_random_model(configs: &RefinerConfigs, dir: &Path, device: &Device) -> Result<(), RefineError> {
    check_vae(&configs.vae, dir)?;
    let mut weights = Weights::random_kept(device);
    drop(Vae::load(&mut weights, &configs.vae)?);
    write_component(dir, "vae", "diffusion_pytorch_model", &configs.vae, &weights.into_made())?;
    let mut weights = Weights::random_kept(device);
    drop(Unet::load(&mut weights, &configs.unet, dir)?);
    write_component(dir, "unet", "diffusion_pytorch_model", &configs.unet, &weights.into_made())?;
    let mut weights = Weights::random_kept(device);
    drop(TextEncoder::load(&mut weights, &configs.text_encoder, dir)?);
    write_component(dir, "text_encoder", "model", &configs.text_encoder, &weights.into_made())?;
    write_component(dir, "scheduler", "", &configs.scheduler, &NamedTensors::new())
}

/// `dir/component/`: its configuration (`config.json`, the scheduler's `scheduler_config.json`) and, when there
/// are any, its tensors as `stem.safetensors`.
fn write_component(
    dir: &Path,
    component: &str,
    stem: &str,
    config: &impl serde::Serialize,
    tensors: &NamedTensors,
) -> Result<(), RefineError> {
    let folder = dir.join(component);
    std::fs::create_dir_all(&folder).map_err(|e| RefineError::io(&folder, e))?;
    let config_path = folder.join(if component == "scheduler" { "scheduler_config.json" } else { "config.json" });
    let text = serde_json::to_string_pretty(config).expect("configurations serialise");
    std::fs::write(&config_path, text).map_err(|e| RefineError::io(&config_path, e))?;
    if tensors.is_empty() {
        return Ok(());
    }
    write_safetensors(&folder.join(format!("{stem}.safetensors")), tensors, HashMap::new())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sd_turbo_has_64_channels_per_head_at_every_level() {
        let configs = RefinerConfigs::sd_turbo();
        let unet = &configs.unet;
        for (level, width) in unet.block_out_channels.iter().enumerate() {
            assert_eq!(width / unet.attention_head_dim.at(level), 64, "level {level}");
        }
        assert_eq!(configs.vae.block_out_channels, [128, 256, 512, 512]);
        assert_eq!((configs.text_encoder.hidden_size, configs.text_encoder.num_hidden_layers), (1024, 23));
    }
}
