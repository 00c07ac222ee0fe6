//! Named host tensors read from checkpoint files, and the builder's view of them: each module takes its
//! tensors by their checkpoint name and expected shape, so a missing or mis-shaped tensor is an error naming
//! the file and the tensor, and whatever no module took is reported.
//!
//! Values are held on the host as f32 (files in f16 or bf16 are widened) because the loader edits some of
//! them before they become parameters: checkpoint overlays replace base tensors and LoRA pairs are merged
//! into their targets ([`crate::lora`]).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use burn::module::ParamId;
use burn::tensor::{DType, Device, Distribution, Tensor, TensorData};
use safetensors::Dtype;

use dggt_model::safetensors_file::{SafetensorsError, SafetensorsFile};

use crate::error::RefineError;

/// One tensor's shape, values (row-major) and the file it was read from.
#[derive(Debug, Clone)]
pub struct HostTensor {
    pub shape: Vec<usize>,
    pub values: Vec<f32>,
    pub file: PathBuf,
}

impl HostTensor {
    /// Widens `data` (any float type) to f32.
    pub fn from_data(data: TensorData, file: &Path, name: &str) -> Result<Self, RefineError> {
        if !matches!(data.dtype(), DType::F64 | DType::F32 | DType::F16 | DType::BF16) {
            return Err(RefineError::file(
                file,
                format!("tensor '{name}' has type {:?}, expected a float", data.dtype()),
            ));
        }
        let shape = data.shape().to_vec();
        let values = data
            .convert::<f32>()
            .try_into_vec::<f32>()
            .map_err(|e| RefineError::file(file, format!("tensor '{name}': {e:?}")))?;
        Ok(Self { shape, values, file: file.to_path_buf() })
    }
}

/// Tensors by checkpoint name.
pub type NamedTensors = BTreeMap<String, HostTensor>;

/// How a parameter holds the tensor of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoredLayout {
    /// As in the file.
    AsFile,
    /// The file's `[out, in]` linear weight transposed to burn's `[in, out]`.
    Transposed,
}

/// Parameters by the name of the file tensor they were loaded from.
pub type ParamNames = BTreeMap<String, (ParamId, StoredLayout)>;

/// Every tensor of a safetensors file.
pub fn read_safetensors(path: &Path) -> Result<NamedTensors, RefineError> {
    Ok(read_safetensors_with_metadata(path)?.0)
}

/// Every tensor of a safetensors file, and the file's text metadata (empty when it has none). The file is
/// read tensor by tensor ([`SafetensorsFile`]: its header first, then each tensor's bytes), so reading holds one
/// tensor's bytes beside the widened values rather than a copy of the whole file. Every tensor must be a float.
pub fn read_safetensors_with_metadata(path: &Path) -> Result<(NamedTensors, HashMap<String, String>), RefineError> {
    let mut file = SafetensorsFile::open(path)?;
    let mut tensors = NamedTensors::new();
    let names: Vec<String> = file.entries().keys().cloned().collect();
    for name in names {
        let entry = file.entry(&name)?;
        if !entry.is_float() {
            let dtype = entry.dtype.clone();
            let path = path.to_path_buf();
            return Err(SafetensorsError::UnsupportedDtype { path, name, dtype, expected: "a float" }.into());
        }
        let data = file.read_data(&name)?;
        tensors.insert(name.clone(), HostTensor::from_data(data, path, &name)?);
    }
    Ok((tensors, std::mem::take(&mut file.metadata)))
}

/// Writes `tensors` (f32) and `metadata` as a safetensors file.
pub fn write_safetensors(
    path: &Path,
    tensors: &NamedTensors,
    metadata: HashMap<String, String>,
) -> Result<(), RefineError> {
    let bytes: Vec<(&String, Vec<u8>, &Vec<usize>)> = tensors
        .iter()
        .map(|(name, t)| (name, t.values.iter().flat_map(|v| v.to_le_bytes()).collect(), &t.shape))
        .collect();
    let views = bytes
        .iter()
        .map(|(name, data, shape)| {
            safetensors::tensor::TensorView::new(Dtype::F32, shape.to_vec(), data)
                .map(|view| (name.to_string(), view))
                .map_err(|e| RefineError::file(path, format!("tensor '{name}': {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    safetensors::serialize_to_file(views, Some(metadata), path).map_err(|e| RefineError::file(path, e.to_string()))
}

/// Where [`Weights::take`] gets a tensor's values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fill {
    /// From the tensors read from files.
    Stored,
    /// Made up for the requested shape (see [`Weights::random`]).
    Random,
}

/// The tensors a module tree is built from, on the device its parameters go to. Taking a tensor marks it
/// used; [`Weights::unused`] lists the rest.
pub struct Weights {
    tensors: NamedTensors,
    /// With [`Weights::random_kept`], host copies of the made-up tensors, by name.
    made: Option<NamedTensors>,
    taken: BTreeSet<String>,
    /// The parameter each taken weight became, by file name (see [`Weights::record`]).
    params: ParamNames,
    source: String,
    device: Device,
    fill: Fill,
}

impl Weights {
    /// `source`: the files the tensors came from, as error messages name them.
    pub fn new(tensors: NamedTensors, source: impl Into<String>, device: &Device) -> Self {
        Self {
            tensors,
            made: None,
            taken: BTreeSet::new(),
            params: ParamNames::new(),
            source: source.into(),
            device: device.clone(),
            fill: Fill::Stored,
        }
    }

    /// Weights that give every requested tensor made-up values of its shape, made on the device (no host
    /// copy), for timing and memory at a size whose weights are not at hand: matrices and kernels uniform with
    /// the variance `1 / fan_in` (fan-in: the product of the dimensions after the first), vectors ones for
    /// normalisation weights (a name containing `norm`) and zeros otherwise.
    pub fn random(device: &Device) -> Self {
        Self { fill: Fill::Random, ..Self::new(NamedTensors::new(), "random weights", device) }
    }

    /// [`Weights::random`], keeping a host copy of every tensor made, in the file's layout
    /// ([`Weights::into_made`]): what writing a made-up model folder needs.
    pub fn random_kept(device: &Device) -> Self {
        Self { made: Some(NamedTensors::new()), ..Self::random(device) }
    }

    /// The tensors made so far by [`Weights::random_kept`] (none for other weights).
    pub fn into_made(self) -> NamedTensors {
        self.made.unwrap_or_default()
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    pub fn contains(&self, name: &str) -> bool {
        self.tensors.contains_key(name)
    }

    /// The tensor `name`, which must have `shape`, as a parameter tensor.
    pub fn take<const D: usize>(&mut self, name: &str, shape: [usize; D]) -> Result<Tensor<D>, RefineError> {
        if self.fill == Fill::Random {
            self.taken.insert(name.to_string());
            let tensor = random_tensor(name, shape, &self.device);
            if let Some(made) = &mut self.made {
                let host = HostTensor::from_data(tensor.to_data(), Path::new(&self.source), name)?;
                made.insert(name.to_string(), host);
            }
            return Ok(tensor);
        }
        self.checked(name, &shape)?;
        let tensor = self.tensors.remove(name).expect("checked: present");
        Ok(Tensor::from_data(TensorData::new(tensor.values, shape), &self.device))
    }

    /// The host copy of the tensor `name`, which must have `shape`, marked used.
    fn checked(&mut self, name: &str, shape: &[usize]) -> Result<&HostTensor, RefineError> {
        let Some(tensor) = self.tensors.get(name) else {
            return Err(RefineError::MissingTensor { path: self.source.clone(), name: name.to_string() });
        };
        if tensor.shape != shape {
            return Err(RefineError::ShapeMismatch {
                path: tensor.file.display().to_string(),
                name: name.to_string(),
                expected: shape.to_vec(),
                found: tensor.shape.clone(),
            });
        }
        self.taken.insert(name.to_string());
        Ok(tensor)
    }

    /// Names of the tensors no module took.
    /// Notes that the tensor `name` became the parameter `id`, stored in `layout`.
    pub fn record(&mut self, name: &str, id: ParamId, layout: StoredLayout) {
        self.params.insert(name.to_string(), (id, layout));
    }

    /// Every recorded parameter by its file name: what lets a trainer find a module's parameter by the name
    /// checkpoints use.
    pub fn params(&self) -> &ParamNames {
        &self.params
    }

    pub fn unused(&self) -> Vec<String> {
        self.tensors.keys().filter(|name| !self.taken.contains(*name)).cloned().collect()
    }
}

/// See [`Weights::random`].
fn random_tensor<const D: usize>(name: &str, shape: [usize; D], device: &Device) -> Tensor<D> {
    if D == 1 {
        return if name.contains("norm") { Tensor::ones(shape, device) } else { Tensor::zeros(shape, device) };
    }
    let fan_in: usize = shape[1..].iter().product();
    let bound = (3.0 / fan_in.max(1) as f64).sqrt();
    Tensor::random(shape, Distribution::Uniform(-bound, bound), device)
}
