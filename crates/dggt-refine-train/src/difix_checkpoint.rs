//! The trained refiner as a Difix checkpoint, and its file.
//!
//! [`to_difix_checkpoint`] gives what `model_difix.pkl` holds: the full UNet state dict, the VAE's skip convolutions
//! (`<module>.base_layer.weight`) and LoRA factors (`<module>.lora_A.vae_skip.weight`, `lora_B`) in peft's
//! names and layouts, the targets and the rank. [`dggt_refine::Refiner::from_checkpoint`] merges the factors,
//! so a trained refiner loads like a released one: [`load_trained_refiner`].
//!
//! The file ([`write_difix_checkpoint`], [`read_difix_checkpoint`]) is the refiner's safetensors form of a Difix checkpoint
//! ([`DifixCheckpoint::write_safetensors`]).

use std::path::Path;

use burn::module::ParamId;
use burn::tensor::{Device, TensorData};
use dggt_refine::checkpoint::DifixCheckpoint;
use dggt_refine::lora::{LORA_ALPHA, lora_names};
use dggt_refine::weights::{HostTensor, NamedTensors, StoredLayout};
use dggt_refine::{LoadReport, Refiner};

use crate::error::RefineTrainError;
use crate::model::{TrainableRefiner, param_values};

/// The trained weights as a Difix checkpoint (see the module's doc).
pub fn to_difix_checkpoint(model: &TrainableRefiner) -> Result<DifixCheckpoint, RefineTrainError> {
    let values = param_values(&model.weights);
    let index = &model.index;
    let host = |id: &ParamId, layout: StoredLayout, name: &str| -> Result<HostTensor, RefineTrainError> {
        let data = values.get(id).ok_or_else(|| RefineTrainError::MissingParameter {
            name: name.to_string(),
            detail: "not a parameter of the refiner",
        })?;
        Ok(host_tensor(data, layout))
    };
    let unet = index
        .unet
        .iter()
        .map(|(name, (id, layout))| Ok((name.clone(), host(id, *layout, name)?)))
        .collect::<Result<NamedTensors, RefineTrainError>>()?;
    let mut vae = NamedTensors::new();
    for (name, (id, layout)) in index.vae.iter().filter(|(name, _)| name.starts_with("decoder.skip_conv_")) {
        let wrapped = name.replacen(".weight", ".base_layer.weight", 1);
        vae.insert(wrapped, host(id, *layout, name)?);
    }
    for (target, adapter) in &index.adapters {
        let (a, b) = (host(&adapter.a, StoredLayout::AsFile, target)?, host(&adapter.b, StoredLayout::AsFile, target)?);
        let weight = index.vae.get(&format!("{target}.weight")).and_then(|(id, _)| values.get(id));
        let kernel = weight.map(|w| w.shape().to_vec()).ok_or_else(|| RefineTrainError::MissingParameter {
            name: target.clone(),
            detail: "a LoRA target without its weight in the refiner",
        })?;
        let (down, up) = peft_factors(a, b, adapter.layout, &kernel);
        let [down_name, up_name] = lora_names(target);
        vae.insert(down_name, down);
        vae.insert(up_name, up);
    }
    Ok(DifixCheckpoint {
        lora_targets: index.adapters.keys().cloned().collect(),
        lora_rank: index.rank,
        lora_alpha: LORA_ALPHA,
        unet,
        vae,
    })
}

/// burn's factors `a`, `b` back to peft's `lora_A` (down) and `lora_B` (up); `kernel`: the target weight's
/// shape.
fn peft_factors(a: HostTensor, b: HostTensor, layout: StoredLayout, kernel: &[usize]) -> (HostTensor, HostTensor) {
    match layout {
        StoredLayout::AsFile => {
            // a = lora_B [out, r] -> [out, r, 1, 1]; b = lora_A flattened [r, in k k] -> the kernel's shape.
            let rank = a.shape[1];
            let mut down = b;
            down.shape = std::iter::once(rank).chain(kernel.iter().skip(1).copied()).collect();
            let mut up = a;
            up.shape = vec![up.shape[0], rank, 1, 1];
            (down, up)
        }
        // a = lora_Aᵀ [in, r], b = lora_Bᵀ [r, out].
        StoredLayout::Transposed => (transposed(&a), transposed(&b)),
    }
}

fn host_tensor(data: &TensorData, layout: StoredLayout) -> HostTensor {
    let tensor = HostTensor {
        shape: data.shape().to_vec(),
        values: data.clone().convert::<f32>().try_into_vec::<f32>().expect("float parameters"),
        file: "trained refiner".into(),
    };
    match layout {
        StoredLayout::AsFile => tensor,
        StoredLayout::Transposed => transposed(&tensor),
    }
}

/// The transpose of a 2-D host tensor.
fn transposed(t: &HostTensor) -> HostTensor {
    let (rows, cols) = (t.shape[0], t.shape[1]);
    let values = (0..cols).flat_map(|c| (0..rows).map(move |r| t.values[r * cols + c])).collect();
    HostTensor { shape: vec![cols, rows], values, file: t.file.clone() }
}

/// Writes `checkpoint` to `path` as safetensors ([`DifixCheckpoint::write_safetensors`]).
pub fn write_difix_checkpoint(checkpoint: &DifixCheckpoint, path: &Path) -> Result<(), RefineTrainError> {
    Ok(checkpoint.write_safetensors(path)?)
}

/// Reads a Difix checkpoint: `model_difix.pkl` or its safetensors form ([`DifixCheckpoint::read`]).
pub fn read_difix_checkpoint(path: &Path) -> Result<DifixCheckpoint, RefineTrainError> {
    Ok(DifixCheckpoint::read(path)?)
}

/// The refiner of a written Difix checkpoint file over its base folder, LoRA merged.
pub fn load_trained_refiner(
    base_dir: &Path,
    checkpoint: &Path,
    prompt_tokens: &[i64],
    device: &Device,
) -> Result<(Refiner, LoadReport), RefineTrainError> {
    Ok(Refiner::from_checkpoint(base_dir, read_difix_checkpoint(checkpoint)?, checkpoint, prompt_tokens, device)?)
}
