//! Difix's refiner checkpoint (`model_difix.pkl`): a `torch.save`d dict holding
//! - `vae_lora_target_modules`: the decoder modules that carry LoRA, full names inside the VAE;
//! - `rank_vae`: the LoRA rank;
//! - `state_dict_unet`: UNet tensors under diffusers names, full or partial, overlaying the base UNet;
//! - `state_dict_vae`: the decoder's LoRA pairs and skip convolutions under peft names
//!   (`<module>.lora_A.<adapter>.weight`, `<module>.base_layer.weight`);
//! - `optimizer`: the training optimiser's state, not read.

use std::path::Path;

use burn::store::pytorch_reader::{self, PickleValue, PytorchReader};
use burn::tensor::{DType, TensorData};

use crate::error::RefineError;
use crate::weights::{HostTensor, NamedTensors};

/// What a refiner checkpoint holds for inference.
#[derive(Debug)]
pub struct DifixCheckpoint {
    pub lora_targets: Vec<String>,
    pub lora_rank: usize,
    pub unet: NamedTensors,
    pub vae: NamedTensors,
}

impl DifixCheckpoint {
    pub fn read(path: &Path) -> Result<Self, RefineError> {
        let lora_targets = match entry(path, "vae_lora_target_modules")? {
            PickleValue::List(items) => items
                .into_iter()
                .map(|item| match item {
                    PickleValue::String(name) => Ok(name),
                    other => {
                        Err(RefineError::file(path, format!("vae_lora_target_modules holds {other:?}, expected names")))
                    }
                })
                .collect::<Result<_, _>>()?,
            other => {
                return Err(RefineError::file(path, format!("vae_lora_target_modules is {other:?}, expected a list")));
            }
        };
        let lora_rank = match entry(path, "rank_vae")? {
            PickleValue::Int(rank) if rank > 0 => rank as usize,
            other => {
                return Err(RefineError::file(path, format!("rank_vae is {other:?}, expected a positive integer")));
            }
        };
        Ok(Self {
            lora_targets,
            lora_rank,
            unet: state_dict(path, "state_dict_unet")?,
            vae: state_dict(path, "state_dict_vae")?,
        })
    }
}

/// The plain value stored under `key` in the checkpoint's top-level dict.
fn entry(path: &Path, key: &str) -> Result<PickleValue, RefineError> {
    PytorchReader::read_pickle_data(path, Some(key)).map_err(|e| RefineError::file(path, format!("entry '{key}': {e}")))
}

/// The tensors of the state dict stored under `key`.
fn state_dict(path: &Path, key: &str) -> Result<NamedTensors, RefineError> {
    let reader = PytorchReader::with_top_level_key(path, key)
        .map_err(|e| RefineError::file(path, format!("entry '{key}': {e}")))?;
    let mut tensors = NamedTensors::new();
    for (name, tensor) in reader.into_tensors() {
        let dtype = match tensor.dtype() {
            pytorch_reader::DType::F64 => DType::F64,
            pytorch_reader::DType::F32 => DType::F32,
            pytorch_reader::DType::F16 => DType::F16,
            pytorch_reader::DType::BF16 => DType::BF16,
            other => {
                return Err(RefineError::file(
                    path,
                    format!("{key}: tensor '{name}' has type {other:?}, expected a float"),
                ));
            }
        };
        let shape = tensor.shape().to_vec();
        let bytes = tensor.read().map_err(|e| RefineError::file(path, format!("{key}: {e}")))?;
        let data = TensorData::from_bytes_vec(bytes, shape, dtype);
        tensors.insert(name.clone(), HostTensor::from_data(data, path, &name)?);
    }
    Ok(tensors)
}
