//! The network of a checkpoint folder: its configuration (`model.json`), the input preprocessing it was trained
//! with (`preprocess.json`; older checkpoints lack it) and its weights (`model.bpk`). Weights are burnpack
//! files, parameter ids included so that an optimiser's state stays attached to them, written tensor by tensor
//! (peak host memory is one tensor, not the whole network) and read back into a module of the same structure;
//! any module is written and read alike (a run's trained weights beside their average, say).

use std::fs;
use std::path::Path;

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Tensor};
use dggt_data::Preprocess;
use dggt_model::ModelConfig;

use crate::error::CheckpointError;
use crate::files::{MODEL_CONFIG_FILE, MODEL_FILE, PREPROCESS_FILE};

fn read(path: &Path) -> Result<Vec<u8>, CheckpointError> {
    fs::read(path).map_err(|e| CheckpointError::file(path, e))
}

/// The network configuration stored in a checkpoint folder.
pub fn read_model_config(dir: &Path) -> Result<ModelConfig, CheckpointError> {
    let path = dir.join(MODEL_CONFIG_FILE);
    serde_json::from_slice(&read(&path)?).map_err(|e| CheckpointError::file(&path, e))
}

/// The input preprocessing a checkpoint folder records; `None` for a checkpoint written before it was recorded.
pub fn read_preprocess(dir: &Path) -> Result<Option<Preprocess>, CheckpointError> {
    let path = dir.join(PREPROCESS_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let preprocess: Preprocess = serde_json::from_slice(&read(&path)?).map_err(|e| CheckpointError::file(&path, e))?;
    preprocess.validate().map_err(|e| CheckpointError::file(&path, e))?;
    Ok(Some(preprocess))
}

/// Loads the network of a checkpoint folder into `model` (built from the stored configuration); any module
/// saved the same way loads alike.
pub fn load_model<M: Module>(dir: &Path, model: M) -> Result<M, CheckpointError> {
    load_module_file(&dir.join(MODEL_FILE), model)
}

/// Loads the module file `path` (burnpack, as a checkpoint writes its modules) into `model`.
pub fn load_module_file<M: Module>(path: &Path, model: M) -> Result<M, CheckpointError> {
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(read(path)?))
        .map_err(|e| CheckpointError::file(path, format!("{e:?}")))?;
    model.try_load_record(record).map_err(|e| CheckpointError::file(path, format!("does not fit the network: {e:?}")))
}

/// Writes a module's (the network's) parameters as a burnpack file readable by [`load_model`], one tensor at a time: each
/// is read back from its device only when the writer reaches it, so saving never holds a host copy of the
/// whole network.
pub fn save_model<M: Module>(path: &Path, model: &M) -> Result<(), CheckpointError> {
    let mut collect = DeferredParameters::default();
    model.visit(&mut collect);
    burn_pack::Writer::new(collect.tensors).write_to_file(path).map_err(|e| CheckpointError::file(path, e))
}

/// Every parameter of a module as a deferred burnpack entry named by its module path, as burn's module records
/// name them.
#[derive(Default)]
struct DeferredParameters {
    path: Vec<String>,
    tensors: Vec<burn_pack::Tensor>,
}

impl ModuleVisitor for DeferredParameters {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let saved = param.transform_for_save().val();
        self.tensors.push(deferred_tensor(self.path.join("."), &saved, &param.id));
    }
}

/// A burnpack entry whose bytes are read from `tensor`'s device only when the writer reaches it.
pub fn deferred_tensor<const D: usize>(name: String, tensor: &Tensor<D>, id: &ParamId) -> burn_pack::Tensor {
    let tensor = tensor.clone();
    let byte_len = tensor.shape().num_elements() * tensor.dtype().size();
    burn_pack::Tensor::deferred(name, tensor.dtype(), tensor.shape(), Some(id.val()), byte_len, move || {
        Ok(tensor.to_data().into_bytes())
    })
}
