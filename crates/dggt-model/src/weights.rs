//! Loading release checkpoints (official PyTorch key names; safetensors or `torch.save` files) into the burn
//! module tree.
//!
//! Module fields carry the release's names, so the only renames are PyTorch's conventions (Linear weights
//! transposed, LayerNorm `weight`/`bias` -> `gamma`/`beta`, done by burn-store's PyTorch adapter) and the
//! [`KEY_RENAMES`]: Sequential indices and camel-case names of the release given Rust names. A shape
//! mismatch is an error naming the tensor and both shapes; a tensor the network needs but the file lacks is an
//! error; tensors in the file that no built module consumes are reported as unused.
//!
//! Memory: a safetensors file is read tensor by tensor with ordinary reads, each into a buffer the parameter then
//! owns, so loading needs about the checkpoint's size once (`benches/checkpoint_load.rs`). burn-store's own
//! safetensors reader memory-maps the file instead, and the mapped pages it touches stay in the process's resident
//! set until the load ends, which put the peak at about twice the file size.

use std::path::Path;

use burn::module::{Module, ModuleVisitor, Param};
use burn::store::burn_pack::{Error as PackError, Tensor as PackTensor};
use burn::store::{ApplyError, KeyRemapper, ModuleSnapshot, PyTorchToBurnAdapter, PytorchStore, bridge};
use burn::tensor::{Bytes, Shape, Tensor, TensorData};

use crate::error::ModelError;
use crate::safetensors_file::{SafetensorsError, SafetensorsFile, read_file_range};

/// Source-key renames from the release's names to the module tree: `(regex, replacement)`.
pub const KEY_RENAMES: &[(&str, &str)] = &[
    (r"\.poseLN_modulation\.1\.", ".pose_ln_modulation."),
    (r"\.resize_layers\.0\.", ".resize_layers.up4."),
    (r"\.resize_layers\.1\.", ".resize_layers.up2."),
    (r"\.resize_layers\.3\.", ".resize_layers.down2."),
    (r"\.resConfUnit([12])\.", ".res_conf_unit${1}."),
    (r"\.output_conv2\.0\.", ".output_conv2.hidden."),
    (r"\.output_conv2\.2\.", ".output_conv2.out."),
];

/// The module path a release checkpoint key is loaded into, before the PyTorch adapter's per-type renames
/// (LayerNorm `weight`/`bias` -> `gamma`/`beta`).
pub fn module_path(release_key: &str) -> String {
    let remapper = KeyRemapper::from_patterns(KEY_RENAMES.to_vec()).expect("KEY_RENAMES are valid regexes");
    remapper.to_regex_pairs().iter().fold(release_key.to_string(), |key, (regex, replacement)| {
        regex.replace_all(&key, replacement.as_str()).into_owned()
    })
}

/// One float parameter of a module tree.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParameterInfo {
    /// Dotted module path, e.g. `aggregator.frame_blocks.0.attn.qkv.weight`.
    pub path: String,
    /// Shape in burn's layout (Linear weights are `[in, out]`).
    pub shape: Vec<usize>,
    /// Type of the module holding it, as burn names it (`Struct:Linear`, `Struct:LayerNorm`, ...).
    pub container: String,
}

/// Every float parameter of `module` with its shape, without initialising lazily created parameters (so a
/// full-size network can be checked against a key list without allocating its weights).
pub fn parameters<M: Module>(module: &M) -> Vec<ParameterInfo> {
    struct Lister {
        path: Vec<String>,
        containers: Vec<String>,
        found: Vec<ParameterInfo>,
    }
    impl ModuleVisitor for Lister {
        fn enter_module(&mut self, name: &str, container_type: &str) {
            self.path.push(name.to_string());
            self.containers.push(container_type.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
            self.containers.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let container = self
                .containers
                .iter()
                .rev()
                .find(|c| c.starts_with("Struct:") || c.starts_with("Enum:"))
                .cloned()
                .unwrap_or_default();
            self.found.push(ParameterInfo { path: self.path.join("."), shape: param.lazy_shape().to_vec(), container });
        }
    }
    let mut lister = Lister { path: vec![], containers: vec![], found: vec![] };
    module.visit(&mut lister);
    lister.found
}

/// What a load consumed.
#[derive(Debug, Clone, Default)]
pub struct LoadReport {
    /// Module paths that received a tensor.
    pub applied: Vec<String>,
    /// Checkpoint tensors (after renaming) that no module parameter took.
    pub unused: Vec<String>,
    /// Module parameters the checkpoint has no tensor for (empty for a strict load); they keep their values.
    pub missing: Vec<String>,
}

/// Whether every parameter of the module must come from the checkpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coverage {
    /// A parameter without a tensor is an error (loading a checkpoint of the same network).
    Complete,
    /// Parameters without a tensor keep their values (starting DGGT from a VGGT checkpoint).
    Partial,
}

/// Loads a checkpoint with release key names into `module`, strictly for every parameter the module has.
/// The format follows the extension: `.safetensors`, or `.pt` / `.pth` (a `torch.save`d state dict; storages
/// tagged with a CUDA device are read on the CPU like any other).
pub fn load_checkpoint<M: Module>(module: &mut M, path: impl AsRef<Path>) -> Result<LoadReport, ModelError> {
    load_checkpoint_with(module, path, Coverage::Complete)
}

/// [`load_checkpoint`] with a choice of [`Coverage`]. Shape and type mismatches are errors either way.
pub fn load_checkpoint_with<M: Module>(
    module: &mut M,
    path: impl AsRef<Path>,
    coverage: Coverage,
) -> Result<LoadReport, ModelError> {
    let path = path.as_ref();
    let file_error = |message: String| ModelError::WeightsFile { path: path.display().to_string(), message };
    let result = match path.extension().and_then(|e| e.to_str()) {
        Some("safetensors") => {
            let renames = KeyRemapper::from_patterns(KEY_RENAMES.to_vec()).expect("KEY_RENAMES are valid regexes");
            let (tensors, _) = renames.remap(safetensors_tensors(path)?);
            module.apply(tensors, None, Some(Box::new(PyTorchToBurnAdapter)), false)
        }
        Some("pt" | "pth") => {
            // The PyTorch store applies the PyTorch adapter itself. Its default renumbering of index gaps
            // (`output_conv2.{0,2}` -> `{0,1}`) would break the renames, so it is turned off.
            let mut store = KEY_RENAMES
                .iter()
                .fold(PytorchStore::from_file(path), |store, (from, to)| store.with_key_remapping(from, *to))
                .map_indices_contiguous(false)
                .allow_partial(true)
                .validate(false);
            module.load_from(&mut store).map_err(|e| file_error(e.to_string()))?
        }
        _ => return Err(file_error("unknown checkpoint format (expected .safetensors, .pt or .pth)".into())),
    };
    report_applied(result, coverage)
}

/// Loads the parameters of `source` into `module` wherever their module paths agree: the parameters of a network
/// trained by this project carried into one built with more (a head added for fine-tuning). Parameters `source`
/// lacks keep their values under [`Coverage::Partial`]; shape and type mismatches are errors either way.
pub fn load_module_from<M: Module, S: Module>(
    module: &mut M,
    source: &S,
    coverage: Coverage,
) -> Result<LoadReport, ModelError> {
    let result = module.apply(source.collect(None, None, false), None, None, false);
    report_applied(result, coverage)
}

/// What an application of tensors did, or the error that names its first problem (every shape mismatch when
/// there are several).
fn report_applied(result: burn::store::ApplyResult, coverage: Coverage) -> Result<LoadReport, ModelError> {
    let mismatched: Vec<String> = result
        .errors
        .iter()
        .filter_map(|error| match error {
            ApplyError::ShapeMismatch { path, expected, found } => {
                Some(format!("{path} (checkpoint {:?}, network {:?})", found.to_vec(), expected.to_vec()))
            }
            _ => None,
        })
        .collect();
    if mismatched.len() > 1 {
        return Err(ModelError::ShapeMismatches(mismatched));
    }
    if let Some(error) = result.errors.first() {
        return Err(match error {
            ApplyError::ShapeMismatch { path, expected, found } => {
                ModelError::ShapeMismatch { name: path.clone(), expected: expected.to_vec(), found: found.to_vec() }
            }
            ApplyError::DTypeMismatch { path, .. }
            | ApplyError::AdapterError { path, .. }
            | ApplyError::LoadError { path, .. } => {
                ModelError::WeightApply { name: path.clone(), message: error.to_string() }
            }
        });
    }
    let missing: Vec<String> = result.missing.iter().map(|(path, _)| path.clone()).collect();
    if coverage == Coverage::Complete && !missing.is_empty() {
        return Err(ModelError::MissingWeights(missing));
    }
    Ok(LoadReport { applied: result.applied, unused: result.unused, missing })
}

/// The tensors of a safetensors file ([`SafetensorsFile`] checks its header: every tensor's byte range lies
/// inside the file and matches its shape and dtype), each read from disk only when the loader takes it.
fn safetensors_tensors(path: &Path) -> Result<Vec<PackTensor>, SafetensorsError> {
    let file = SafetensorsFile::open(path)?;
    let mut tensors = Vec::new();
    for (name, entry) in file.entries() {
        let dtype = entry.burn_dtype().ok_or_else(|| SafetensorsError::UnsupportedDtype {
            path: path.to_path_buf(),
            name: name.clone(),
            dtype: entry.dtype.clone(),
            expected: "a type burn holds",
        })?;
        let shape = Shape::from(entry.shape.clone());
        let (source, range) = (path.to_path_buf(), file.byte_range(name)?);
        tensors.push(bridge::deferred(name.clone(), dtype, shape.clone(), None, move || {
            let bytes = read_file_range(&source, range.clone()).map_err(|e| PackError::IoError(e.to_string()))?;
            TensorData::try_from_bytes(Bytes::from_bytes_vec(bytes), shape.clone(), dtype)
                .map_err(|e| PackError::TensorBytesSizeMismatch(e.to_string()))
        }));
    }
    Ok(tensors)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Dggt, ModelConfig};
    use burn::tensor::Device;

    #[test]
    fn release_keys_map_to_module_paths() {
        assert_eq!(module_path("camera_head.poseLN_modulation.1.weight"), "camera_head.pose_ln_modulation.weight");
        assert_eq!(
            module_path("depth_head.scratch.refinenet1.resConfUnit2.conv1.bias"),
            "depth_head.scratch.refinenet1.res_conf_unit2.conv1.bias"
        );
        assert_eq!(module_path("gs_head.resize_layers.3.weight"), "gs_head.resize_layers.down2.weight");
        assert_eq!(module_path("gs_head.scratch.output_conv2.2.bias"), "gs_head.scratch.output_conv2.out.bias");
        assert_eq!(module_path("aggregator.frame_blocks.0.ls1.gamma"), "aggregator.frame_blocks.0.ls1.gamma");
    }

    #[test]
    fn truncated_safetensors_is_an_error_naming_file_and_tensor() {
        let path = std::env::temp_dir().join(format!("dggt-truncated-{}.safetensors", std::process::id()));
        let header = br#"{"aggregator.camera_token":{"dtype":"F32","shape":[1,2,1,64],"data_offsets":[0,512]}}"#;
        let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
        bytes.extend_from_slice(header);
        bytes.extend_from_slice(&[0u8; 100]);
        std::fs::write(&path, &bytes).unwrap();
        let mut model = Dggt::new(&ModelConfig::tiny(), &Device::flex()).unwrap();
        let truncated = load_checkpoint_with(&mut model, &path, Coverage::Partial).unwrap_err().to_string();
        // A header length pointing past the end of the file.
        std::fs::write(&path, 1000u64.to_le_bytes()).unwrap();
        let bad_header = load_checkpoint_with(&mut model, &path, Coverage::Partial).unwrap_err().to_string();
        std::fs::remove_file(&path).unwrap();
        let file_name = path.file_name().unwrap().to_str().unwrap();
        assert!(truncated.contains(file_name) && truncated.contains("aggregator.camera_token"), "{truncated}");
        assert!(truncated.contains("expected 512 bytes"), "{truncated}");
        assert!(bad_header.contains(file_name) && bad_header.contains("header length 1000"), "{bad_header}");
    }

    #[test]
    fn parameters_are_listed_without_materialising() {
        let model = Dggt::new(&ModelConfig::tiny(), &Device::flex()).unwrap();
        let params = parameters(&model);
        let qkv = params.iter().find(|p| p.path == "aggregator.frame_blocks.0.attn.qkv.weight").unwrap();
        assert_eq!(qkv.shape, vec![64, 192]);
        assert_eq!(qkv.container, "Struct:Linear");
        let norm = params.iter().find(|p| p.path == "aggregator.frame_blocks.0.attn.q_norm.gamma").unwrap();
        assert_eq!(norm.container, "Struct:LayerNorm");
    }
}
