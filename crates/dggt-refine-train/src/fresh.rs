//! The Difix checkpoint a training run starts from when it has only the base model (sd-turbo), as Difix's
//! training builds its refiner: the UNet as the base has it; skip convolutions added to the decoder with
//! every weight 1e-5 (so they start as a near-no-op); LoRA of rank `rank` on every decoder convolution
//! (`conv_in`, `conv1`, `conv2`, `conv_shortcut`, the upsamplers' `conv`, `conv_out`, the skip convolutions)
//! and the mid-block attention projections (`to_q`, `to_k`, `to_v`, `to_out.0`), with peft's Gaussian
//! initialisation: `lora_A` drawn from N(0, 1/rank²) (standard deviation `1 / rank`), `lora_B` zero, so the
//! decoder starts exactly as the base's.

use std::path::Path;

use dggt_refine::checkpoint::DifixCheckpoint;
use dggt_refine::config::{VaeConfig, read_json};
use dggt_refine::lora::{LORA_ALPHA, lora_names};
use dggt_refine::refiner::{standard_normal_values, weights_file};
use dggt_refine::weights::{HostTensor, NamedTensors, read_safetensors};

use crate::error::RefineTrainError;

/// The starting value of every skip-convolution weight.
pub const SKIP_INIT: f32 = 1e-5;

/// The last name components of the decoder modules that carry LoRA.
const TARGET_ENDINGS: [&str; 10] =
    ["conv_in", "conv1", "conv2", "conv_shortcut", "conv", "conv_out", "to_q", "to_k", "to_v", "to_out.0"];

/// The checkpoint described in the module's doc; target `k`'s `lora_A` is drawn from seed `seed + k`.
pub fn fresh_checkpoint(base_dir: &Path, rank: usize, seed: u64) -> Result<DifixCheckpoint, RefineTrainError> {
    if rank == 0 {
        return Err(RefineTrainError::Setting { setting: "model.lora_rank", detail: "must be at least 1".into() });
    }
    let vae_dir = base_dir.join("vae");
    let config: VaeConfig = read_json(&vae_dir.join("config.json"))?;
    let file = weights_file(&vae_dir, "diffusion_pytorch_model")?;
    let base = read_safetensors(&file)?;
    let mut vae = NamedTensors::new();
    let mut targets: Vec<(String, Vec<usize>)> = base
        .iter()
        .filter_map(|(name, tensor)| {
            let module = name.strip_prefix("decoder.")?.strip_suffix(".weight")?;
            let is_target = TARGET_ENDINGS.iter().any(|end| module == *end || module.ends_with(&format!(".{end}")));
            (is_target && tensor.shape.len() >= 2).then(|| (format!("decoder.{module}"), tensor.shape.clone()))
        })
        .collect();
    for (i, shape) in skip_shapes(&config).into_iter().enumerate() {
        let module = format!("decoder.skip_conv_{}", i + 1);
        let count = shape.iter().product();
        vae.insert(format!("{module}.base_layer.weight"), host(shape.clone(), vec![SKIP_INIT; count], &file));
        targets.push((module, shape));
    }
    for (k, (module, shape)) in targets.iter().enumerate() {
        let down_shape: Vec<usize> = std::iter::once(rank).chain(shape[1..].iter().copied()).collect();
        let normal = standard_normal_values(down_shape.iter().product(), seed.wrapping_add(k as u64));
        let down = normal.into_iter().map(|v| v / rank as f32).collect();
        let up_shape: Vec<usize> = [shape[0], rank].into_iter().chain(shape[2..].iter().map(|_| 1)).collect();
        let up = vec![0.0; up_shape.iter().product()];
        let [down_name, up_name] = lora_names(module);
        vae.insert(down_name, host(down_shape, down, &file));
        vae.insert(up_name, host(up_shape, up, &file));
    }
    let lora_targets = targets.into_iter().map(|(module, _)| module).collect();
    Ok(DifixCheckpoint { lora_targets, lora_rank: rank, lora_alpha: LORA_ALPHA, unet: NamedTensors::new(), vae })
}

/// `[out, in, 1, 1]` of `skip_conv_1..N`: encoder down input `N-1-i` projected to the width entering decoder
/// up block `i` (the layout `dggt_refine::vae` loads).
fn skip_shapes(config: &VaeConfig) -> Vec<Vec<usize>> {
    let widths = &config.block_out_channels;
    let levels = widths.len();
    (0..levels)
        .map(|i| {
            let source = widths[(levels - 1 - i).saturating_sub(1)];
            let target = widths[levels - 1 - i.saturating_sub(1)];
            vec![target, source, 1, 1]
        })
        .collect()
}

fn host(shape: Vec<usize>, values: Vec<f32>, file: &Path) -> HostTensor {
    HostTensor { shape, values, file: file.to_path_buf() }
}
