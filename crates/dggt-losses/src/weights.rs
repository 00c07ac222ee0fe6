//! Reading named tensors from PyTorch-style weight files: `.safetensors`, or `.pt` / `.pth` (a `torch.save`d
//! state dict), through burn's stores.
//!
//! The networks of this crate hold their weights as plain tensors, not trainable parameters: they are looked
//! up here by name (with alternative spellings, e.g. torchvision's `features.3.weight` and the lpips
//! package's `net.slice2.3.weight`), checked against the expected shape and converted to f32 on the target
//! device. A tensor built this way never requires a gradient, so on an autodiff device the networks are
//! frozen while gradients still flow through them to their inputs.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::store::burn_pack::Tensor as PackTensor;
use burn::store::{ModuleStore, PytorchStore, SafetensorsStore, bridge};
use burn::tensor::{Device, Tensor};

use crate::error::LossError;

/// The tensors of one weight file, read lazily (only looked-up tensors are loaded).
pub struct WeightFile {
    path: PathBuf,
    tensors: BTreeMap<String, PackTensor>,
}

impl std::fmt::Debug for WeightFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WeightFile").field("path", &self.path).field("tensors", &self.tensors.len()).finish()
    }
}

impl WeightFile {
    /// Opens a `.safetensors`, `.pt` or `.pth` file and lists its tensors.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, LossError> {
        let path = path.as_ref();
        let file_error = |message: String| LossError::WeightsFile { path: path.display().to_string(), message };
        if !path.is_file() {
            return Err(file_error("no such file".into()));
        }
        let tensors = match path.extension().and_then(|e| e.to_str()) {
            Some("safetensors") => {
                let mut store = SafetensorsStore::from_file(path);
                store.get_all_tensors().map_err(|e| file_error(e.to_string()))?.clone()
            }
            Some("pt" | "pth") => {
                let mut store = PytorchStore::from_file(path).map_indices_contiguous(false);
                store.get_all_tensors().map_err(|e| file_error(e.to_string()))?.clone()
            }
            _ => return Err(file_error("unknown weight format (expected .safetensors, .pt or .pth)".into())),
        };
        Ok(Self { path: path.to_path_buf(), tensors })
    }

    /// The file this was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Names of all tensors in the file, sorted.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(String::as_str)
    }

    /// Shape of the tensor `name`, if the file has it.
    pub fn shape(&self, name: &str) -> Option<Vec<usize>> {
        self.tensors.get(name).map(|t| t.shape.to_vec())
    }

    /// The tensor stored under the first of `names` that the file has, as f32 on `device`, after checking its
    /// shape against `expected`. The error for a missing tensor names `names[0]` and lists the others.
    pub fn tensor<const D: usize>(
        &self,
        names: &[String],
        expected: [usize; D],
        device: &Device,
    ) -> Result<Tensor<D>, LossError> {
        let path = self.path.display().to_string();
        let Some((name, entry)) = names.iter().find_map(|n| self.tensors.get(n).map(|t| (n, t))) else {
            return Err(LossError::MissingTensor {
                path,
                name: names.first().cloned().unwrap_or_default(),
                aliases: names.iter().skip(1).cloned().collect(),
                expected: expected.to_vec(),
            });
        };
        let found = entry.shape.to_vec();
        if found != expected {
            return Err(LossError::ShapeMismatch { path, name: name.clone(), expected: expected.to_vec(), found });
        }
        let data = bridge::to_data(entry).map_err(|e| LossError::TensorData {
            path: path.clone(),
            name: name.clone(),
            message: e.to_string(),
        })?;
        if !data.dtype().is_float() {
            return Err(LossError::TensorData {
                path,
                name: name.clone(),
                message: format!("dtype {:?} is not a float type", data.dtype()),
            });
        }
        Ok(Tensor::from_data(data.convert::<f32>(), device))
    }
}
