//! The trained refiner as a Difix checkpoint, and its file.
//!
//! [`to_checkpoint`] gives what `model_difix.pkl` holds: the full UNet state dict, the VAE's skip convolutions
//! (`<module>.base_layer.weight`) and LoRA factors (`<module>.lora_A.vae_skip.weight`, `lora_B`) in peft's
//! names and layouts, the targets and the rank. [`dggt_refine::Refiner::from_checkpoint`] merges the factors,
//! so a trained refiner loads like a released one: [`load_refiner`].
//!
//! The file ([`write`], [`read_checkpoint`]) is safetensors, float32: tensors `unet.<name>` and `vae.<name>`,
//! metadata `rank_vae` (an integer) and `vae_lora_target_modules` (a JSON list of names).

use std::collections::HashMap;
use std::path::Path;

use burn::module::ParamId;
use burn::tensor::{Device, TensorData};
use dggt_refine::checkpoint::DifixCheckpoint;
use dggt_refine::lora::lora_names;
use dggt_refine::weights::{HostTensor, NamedTensors, StoredLayout, read_safetensors};
use dggt_refine::{LoadReport, Refiner};

use crate::error::RefineTrainError;
use crate::model::{TrainableRefiner, param_values};

const UNET_PREFIX: &str = "unet.";
const VAE_PREFIX: &str = "vae.";
const RANK_KEY: &str = "rank_vae";
const TARGETS_KEY: &str = "vae_lora_target_modules";

/// The trained weights as a Difix checkpoint (see the module's doc).
pub fn to_checkpoint(model: &TrainableRefiner) -> Result<DifixCheckpoint, RefineTrainError> {
    let values = param_values(&model.weights);
    let index = &model.index;
    let host = |id: &ParamId, layout: StoredLayout, what: &str| -> Result<HostTensor, RefineTrainError> {
        let data = values.get(id).ok_or_else(|| RefineTrainError::invalid(what, "not a parameter of the refiner"))?;
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
        let kernel = weight.map(|w| w.shape().to_vec()).ok_or_else(|| {
            RefineTrainError::invalid(target.as_str(), "a LoRA target without its weight in the refiner")
        })?;
        let (down, up) = peft_factors(a, b, adapter.layout, &kernel);
        let [down_name, up_name] = lora_names(target);
        vae.insert(down_name, down);
        vae.insert(up_name, up);
    }
    Ok(DifixCheckpoint { lora_targets: index.adapters.keys().cloned().collect(), lora_rank: index.rank, unet, vae })
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

/// Writes `checkpoint` to `path` (see the module's doc), atomically.
pub fn write(checkpoint: &DifixCheckpoint, path: &Path) -> Result<(), RefineTrainError> {
    let bytes: Vec<(String, Vec<u8>, Vec<usize>)> = [(UNET_PREFIX, &checkpoint.unet), (VAE_PREFIX, &checkpoint.vae)]
        .into_iter()
        .flat_map(|(prefix, tensors)| {
            tensors.iter().map(move |(name, t)| {
                (format!("{prefix}{name}"), t.values.iter().flat_map(|v| v.to_le_bytes()).collect(), t.shape.clone())
            })
        })
        .collect();
    let views = bytes
        .iter()
        .map(|(name, data, shape)| {
            let view = safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), data)
                .expect("sizes agree");
            (name.clone(), view)
        })
        .collect::<Vec<_>>();
    let metadata: HashMap<String, String> = [
        (RANK_KEY.to_string(), checkpoint.lora_rank.to_string()),
        (TARGETS_KEY.to_string(), serde_json::to_string(&checkpoint.lora_targets).expect("names serialise")),
    ]
    .into();
    let file = safetensors::serialize(views, Some(metadata))
        .map_err(|e| RefineTrainError::invalid(path.display().to_string(), e.to_string()))?;
    dggt_data::io::write_atomically(path, &file)
        .map_err(|e| RefineTrainError::invalid(path.display().to_string(), e.to_string()))
}

/// Reads a Difix checkpoint: `model_difix.pkl` (any extension but `.safetensors`) or a file of [`write`].
pub fn read_checkpoint(path: &Path) -> Result<DifixCheckpoint, RefineTrainError> {
    if path.extension().is_none_or(|e| e != "safetensors") {
        return Ok(DifixCheckpoint::read(path)?);
    }
    let invalid = |detail: String| RefineTrainError::invalid(path.display().to_string(), detail);
    let bytes = std::fs::read(path).map_err(|source| RefineTrainError::Io { path: path.into(), source })?;
    let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).map_err(|e| invalid(e.to_string()))?;
    let metadata = header.metadata().clone().unwrap_or_default();
    let rank = metadata
        .get(RANK_KEY)
        .and_then(|r| r.parse::<usize>().ok())
        .filter(|&r| r > 0)
        .ok_or_else(|| invalid(format!("metadata `{RANK_KEY}` missing or not a positive integer")))?;
    let targets: Vec<String> = metadata
        .get(TARGETS_KEY)
        .and_then(|t| serde_json::from_str(t).ok())
        .ok_or_else(|| invalid(format!("metadata `{TARGETS_KEY}` missing or not a JSON list of names")))?;
    let (mut unet, mut vae) = (NamedTensors::new(), NamedTensors::new());
    for (name, tensor) in read_safetensors(path)? {
        if let Some(rest) = name.strip_prefix(UNET_PREFIX) {
            unet.insert(rest.to_string(), tensor);
        } else if let Some(rest) = name.strip_prefix(VAE_PREFIX) {
            vae.insert(rest.to_string(), tensor);
        } else {
            return Err(invalid(format!("tensor '{name}' is neither unet.* nor vae.*")));
        }
    }
    Ok(DifixCheckpoint { lora_targets: targets, lora_rank: rank, unet, vae })
}

/// The refiner of an exported file over its base folder, LoRA merged.
pub fn load_refiner(
    base_dir: &Path,
    exported: &Path,
    prompt_tokens: &[i64],
    device: &Device,
) -> Result<(Refiner, LoadReport), RefineTrainError> {
    Ok(Refiner::from_checkpoint(base_dir, read_checkpoint(exported)?, exported, prompt_tokens, device)?)
}
