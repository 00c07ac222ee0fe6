//! The network's reference vector folders: `config.json`, `weights.safetensors` or `weights.pt`,
//! `inputs.safetensors` and `outputs.safetensors`, read into memory (weights excepted: they are loaded into the
//! network).

use std::path::{Path, PathBuf};

use burn::tensor::{Device, Tensor, TensorData};
use dggt_model::ModelConfig;
use dggt_model::safetensors_file::{F32Tensor, SafetensorsError, SafetensorsFile};

use crate::error::ParityError;

/// The files of a vector folder; the weights may be either of [`WEIGHT_FILES`].
pub const VECTOR_FILES: [&str; 3] = ["config.json", "inputs.safetensors", "outputs.safetensors"];

/// Weight files looked for in a vector folder, in order of preference.
pub const WEIGHT_FILES: [&str; 2] = ["weights.safetensors", "weights.pt"];

/// A tensor on the host: row-major values and a shape.
#[derive(Debug, Clone, PartialEq)]
pub struct HostTensor {
    pub shape: Vec<usize>,
    pub values: Vec<f32>,
}

impl HostTensor {
    pub fn new(shape: Vec<usize>, values: Vec<f32>) -> Self {
        assert_eq!(shape.iter().product::<usize>(), values.len(), "{shape:?} does not hold {} values", values.len());
        Self { shape, values }
    }

    pub fn from_tensor<const D: usize>(tensor: Tensor<D>) -> Self {
        let shape = tensor.dims().to_vec();
        let values = tensor.into_data().convert::<f32>().try_into_vec::<f32>().expect("converted to f32");
        Self { shape, values }
    }

    /// The tensor on `device`, or `None` when it does not have `D` dimensions.
    pub fn to_tensor<const D: usize>(&self, device: &Device) -> Option<Tensor<D>> {
        let shape: [usize; D] = self.shape.clone().try_into().ok()?;
        Some(Tensor::from_data(TensorData::new(self.values.clone(), shape), device))
    }

    pub fn max_abs(&self) -> f32 {
        self.values.iter().fold(0.0f32, |m, v| m.max(v.abs()))
    }
}

impl From<F32Tensor> for HostTensor {
    fn from(tensor: F32Tensor) -> Self {
        Self { shape: tensor.shape, values: tensor.values }
    }
}

/// Every tensor of a safetensors file in file order, as `f32` (floating-point, integer and boolean tensors are
/// converted).
pub fn read_tensors(path: impl AsRef<Path>) -> Result<Vec<(String, HostTensor)>, SafetensorsError> {
    let mut file = SafetensorsFile::open(path)?;
    file.names_in_file_order()
        .into_iter()
        .map(|name| {
            let tensor = file.read_f32(&name)?;
            Ok((name, tensor.into()))
        })
        .collect()
}

/// A folder of reference vectors, read into memory (weights excepted: they are loaded into the network).
#[derive(Debug, Clone)]
pub struct ParityVectors {
    pub dir: PathBuf,
    pub config: ModelConfig,
    pub inputs: Vec<(String, HostTensor)>,
    /// In file order.
    pub outputs: Vec<(String, HostTensor)>,
}

impl ParityVectors {
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ParityError> {
        let dir = dir.as_ref();
        if !dir.is_dir() {
            return Err(ParityError::NoFolder { dir: dir.to_path_buf() });
        }
        if let Some(missing) = VECTOR_FILES.iter().find(|file| !dir.join(file).is_file()) {
            let holds = format!("{}, and {} or {}", VECTOR_FILES.join(", "), WEIGHT_FILES[0], WEIGHT_FILES[1]);
            return Err(ParityError::MissingFile { dir: dir.to_path_buf(), file: missing, holds });
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            config: ModelConfig::from_parity_json(dir.join("config.json"))?,
            inputs: read_tensors(dir.join("inputs.safetensors"))?,
            outputs: read_tensors(dir.join("outputs.safetensors"))?,
        })
    }

    /// The first of [`WEIGHT_FILES`] present in the folder.
    pub fn default_weights(&self) -> Result<PathBuf, ParityError> {
        WEIGHT_FILES
            .iter()
            .map(|file| self.dir.join(file))
            .find(|path| path.is_file())
            .ok_or_else(|| ParityError::NoWeights { dir: self.dir.clone(), files: WEIGHT_FILES })
    }

    pub fn input(&self, name: &str) -> Option<&HostTensor> {
        self.inputs.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }

    pub fn output(&self, name: &str) -> Option<&HostTensor> {
        self.outputs.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }

    /// The `images` input, `[B, S, 3, H, W]` RGB in `[0, 1]`.
    pub fn images(&self, device: &Device) -> Result<Tensor<5>, ParityError> {
        let dir = self.dir.clone();
        let images = self.input("images").ok_or(ParityError::MissingInput { dir: dir.clone(), name: "images" })?;
        images.to_tensor(device).ok_or_else(|| ParityError::BadInput {
            dir,
            name: "images",
            expected: "[B, S, 3, H, W]".into(),
            found: format!("{:?}", images.shape),
        })
    }
}
