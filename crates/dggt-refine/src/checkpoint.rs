//! Difix's refiner checkpoint (`model_difix.pkl`): a `torch.save`d dict holding
//! - `vae_lora_target_modules`: the decoder modules that carry LoRA, full names inside the VAE;
//! - `rank_vae`: the LoRA rank;
//! - `state_dict_unet`: UNet tensors under diffusers names, full or partial, overlaying the base UNet;
//! - `state_dict_vae`: the decoder's LoRA pairs and skip convolutions under peft names
//!   (`<module>.lora_A.<adapter>.weight`, `<module>.base_layer.weight`);
//! - `optimizer`: the training optimiser's state, not read.
//!
//! The same content converts to a safetensors file ([`DifixCheckpoint::write_safetensors`]), which loads
//! without a pickle reader: the UNet tensors under `unet.<name>`, the VAE's under `vae.<name>` (the peft
//! names kept), all f32, and the text metadata `format` = [`SAFETENSORS_FORMAT`], `vae_lora_target_modules`
//! (a JSON list of names), `rank_vae` and `lora_alpha`. [`DifixCheckpoint::read`] takes either file, by its
//! extension.

use std::collections::HashMap;
use std::path::Path;

use burn::store::pytorch_reader::{self, PickleValue, PytorchReader};
use burn::tensor::{DType, TensorData};

use crate::error::RefineError;
use crate::lora::LORA_ALPHA;
use crate::weights::{HostTensor, NamedTensors, read_safetensors_with_metadata, write_safetensors};

/// The `format` metadata of a converted checkpoint.
pub const SAFETENSORS_FORMAT: &str = "difix-refiner-checkpoint";

/// What a refiner checkpoint holds for inference.
#[derive(Debug)]
pub struct DifixCheckpoint {
    pub lora_targets: Vec<String>,
    pub lora_rank: usize,
    /// LoRA scale numerator: updates are `lora_alpha / lora_rank * B A`.
    pub lora_alpha: f32,
    pub unet: NamedTensors,
    pub vae: NamedTensors,
}

impl DifixCheckpoint {
    /// A converted checkpoint (`.safetensors`) or Difix's own (any other extension).
    pub fn read(path: &Path) -> Result<Self, RefineError> {
        if path.extension().is_some_and(|ext| ext == "safetensors") {
            Self::read_safetensors(path)
        } else {
            Self::read_pickle(path)
        }
    }

    /// Difix's `torch.save`d checkpoint.
    pub fn read_pickle(path: &Path) -> Result<Self, RefineError> {
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
            lora_alpha: LORA_ALPHA,
            unet: state_dict(path, "state_dict_unet")?,
            vae: state_dict(path, "state_dict_vae")?,
        })
    }

    /// A checkpoint converted by [`DifixCheckpoint::write_safetensors`].
    pub fn read_safetensors(path: &Path) -> Result<Self, RefineError> {
        let (tensors, metadata) = read_safetensors_with_metadata(path)?;
        let field = |key: &str| {
            metadata.get(key).ok_or_else(|| RefineError::file(path, format!("metadata '{key}' is missing")))
        };
        let format = field("format")?;
        if format != SAFETENSORS_FORMAT {
            return Err(RefineError::file(
                path,
                format!("metadata format '{format}', expected '{SAFETENSORS_FORMAT}'"),
            ));
        }
        let invalid = |key: &str, what: &str| RefineError::file(path, format!("metadata '{key}' is not {what}"));
        let lora_targets = serde_json::from_str(field("vae_lora_target_modules")?)
            .map_err(|_| invalid("vae_lora_target_modules", "a JSON list of names"))?;
        let lora_rank = field("rank_vae")?.parse().ok().filter(|&r: &usize| r > 0);
        let lora_rank = lora_rank.ok_or_else(|| invalid("rank_vae", "a positive integer"))?;
        let lora_alpha = field("lora_alpha")?.parse().map_err(|_| invalid("lora_alpha", "a number"))?;
        let (mut unet, mut vae) = (NamedTensors::new(), NamedTensors::new());
        for (name, tensor) in tensors {
            match name.split_once('.') {
                Some(("unet", rest)) => unet.insert(rest.to_string(), tensor),
                Some(("vae", rest)) => vae.insert(rest.to_string(), tensor),
                _ => return Err(RefineError::file(path, format!("tensor '{name}' is neither unet.* nor vae.*"))),
            };
        }
        Ok(Self { lora_targets, lora_rank, lora_alpha, unet, vae })
    }

    /// Writes the checkpoint as safetensors (see the module's doc).
    pub fn write_safetensors(&self, path: &Path) -> Result<(), RefineError> {
        let prefixed = |prefix: &str, tensors: &NamedTensors| {
            tensors.iter().map(|(name, t)| (format!("{prefix}.{name}"), t.clone())).collect::<Vec<_>>()
        };
        let tensors: NamedTensors =
            prefixed("unet", &self.unet).into_iter().chain(prefixed("vae", &self.vae)).collect();
        let targets = serde_json::to_string(&self.lora_targets).expect("names serialise");
        let metadata = HashMap::from([
            ("format".to_string(), SAFETENSORS_FORMAT.to_string()),
            ("vae_lora_target_modules".to_string(), targets),
            ("rank_vae".to_string(), self.lora_rank.to_string()),
            ("lora_alpha".to_string(), self.lora_alpha.to_string()),
        ]);
        write_safetensors(path, &tensors, metadata)
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
