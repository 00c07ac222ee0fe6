//! The network a reconstruction runs, from any of the checkpoints users have:
//!
//! - this project's trainer checkpoints: a `step-N` folder (`model.bpk` + `model.json`, the architecture
//!   inside), a run's `checkpoints/` folder or the run folder itself (its `latest` checkpoint);
//! - release files (`.pt`, `.pth`, `.safetensors`, the release's key names): the DGGT release checkpoint, or a
//!   VGGT-1B checkpoint whose Gaussian, dynamic and sky modules are then left untrained. Their architecture comes
//!   from `--config` (a model `config.json`, or a training `.toml` whose `[model]` section is used) or a preset.
//!
//! Modules the checkpoint has no weights for are reported as fresh; a checkpoint missing the core (aggregator,
//! camera or depth head) or matching nothing is refused.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_data::Preprocess;
use dggt_model::sky::SkyModel;
use dggt_model::weights::{Coverage, load_checkpoint_with};
use dggt_model::{Dggt, ModelConfig};
use dggt_scene::AssemblySettings;
use dggt_train::{TrainConfig, checkpoint, model_config};
use serde::Serialize;

use crate::error::ReconstructError;

/// Where the architecture of a release-format checkpoint comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Architecture {
    /// A model `config.json` (the parity-vector layout) or a training configuration `.toml`.
    Config(PathBuf),
    /// `tiny`, `vggt_1b` or `dggt`.
    Preset(String),
}

/// The default architecture of release-format checkpoints.
pub const DEFAULT_PRESET: &str = "dggt";

/// Modules without which nothing can be reconstructed.
const CORE_MODULES: [&str; 3] = ["aggregator", "camera_head", "depth_head"];
/// Modules whose absence leaves the 4D outputs meaningless.
const SCENE_MODULES: [&str; 3] = ["gs_head", "instance_head", "sky_model"];

/// What was loaded, for the summary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckpointInfo {
    pub path: PathBuf,
    /// `trainer` (this project's checkpoint folder) or `release` (`.pt` / `.safetensors`).
    pub format: String,
    /// Where the architecture came from.
    pub architecture: String,
    pub parameters: usize,
    /// Top-level modules the checkpoint had no weights for (they keep fresh values).
    pub fresh_modules: Vec<String>,
}

/// A network ready to run, with the preprocessing its architecture source implies (if any).
pub struct LoadedNetwork {
    pub model: Dggt,
    pub config: ModelConfig,
    pub info: CheckpointInfo,
    /// The preprocessing of a training `.toml` given as `--config`.
    pub preprocess: Option<Preprocess>,
    /// How targets are assembled and rasterised: as the training `.toml` given as `--config` rendered them
    /// (its `render` section: dynamic blend, `eps2d`, far plane), else as the release does.
    pub assembly: AssemblySettings,
    pub warnings: Vec<String>,
}

/// Loads `path` on `device`.
pub fn load_network(
    path: &Path,
    architecture: Option<&Architecture>,
    device: &Device,
) -> Result<LoadedNetwork, ReconstructError> {
    let fail = |detail: String| ReconstructError::Checkpoint { path: path.to_path_buf(), detail };
    if !path.exists() {
        return Err(fail("does not exist".into()));
    }
    let (config_from_arch, training, arch_name) = match architecture {
        Some(arch) => {
            let (config, training, name) = read_architecture(arch)?;
            (Some(config), training, name)
        }
        None => (None, None, String::new()),
    };
    let preprocess = training.as_ref().map(|t| t.data.preprocess.clone());
    let assembly = training.as_ref().map_or(AssemblySettings::default(), |t| t.render.assembly());
    let mut warnings = Vec::new();
    if path.is_dir() {
        let dir = trainer_checkpoint_dir(path)?;
        let config = checkpoint::read_model_config(&dir)?;
        if config_from_arch.as_ref().is_some_and(|c| c != &config) {
            warnings
                .push(format!("{} stores its own architecture; the one from {arch_name} is ignored", dir.display()));
        }
        let model = checkpoint::load_model(&dir, Dggt::new(&config, device)?)?;
        let info = CheckpointInfo {
            path: dir.clone(),
            format: "trainer".into(),
            architecture: format!("{}", dir.join("model.json").display()),
            parameters: burn::module::Module::num_params(&model),
            fresh_modules: Vec::new(),
        };
        return Ok(LoadedNetwork { model, config, info, preprocess, assembly, warnings });
    }

    let (config, arch_name) = match config_from_arch {
        Some(config) => (config, arch_name),
        None => (model_config(DEFAULT_PRESET)?, format!("preset `{DEFAULT_PRESET}`")),
    };
    let mut model = Dggt::new(&config, device)?;
    if let Some(sky) = &config.sky_model {
        model.sky_model = Some(SkyModel::initialised(sky, device));
    }
    let report = load_checkpoint_with(&mut model, path, Coverage::Partial).map_err(|e| match e {
        dggt_model::ModelError::WeightsFile { message, .. } => fail(format!("cannot be read: {message}")),
        other => fail(format!("does not fit the architecture of {arch_name}: {other}")),
    })?;
    if report.applied.is_empty() {
        return Err(fail(format!(
            "no tensor in it matches the network of {arch_name} (not a DGGT or VGGT checkpoint?)"
        )));
    }
    let mut fresh: Vec<String> = report.missing.iter().map(|p| p.split('.').next().unwrap_or(p).to_string()).collect();
    fresh.sort();
    fresh.dedup();
    let missing_core: Vec<&String> = fresh.iter().filter(|m| CORE_MODULES.contains(&m.as_str())).collect();
    if !missing_core.is_empty() {
        let examples: Vec<&String> = report.missing.iter().take(3).collect();
        return Err(fail(format!(
            "lacks weights of {missing_core:?} that the architecture of {arch_name} needs ({} tensors missing, e.g. \
             {examples:?})",
            report.missing.len()
        )));
    }
    let untrained: Vec<&String> = fresh.iter().filter(|m| SCENE_MODULES.contains(&m.as_str())).collect();
    if !untrained.is_empty() {
        warnings.push(format!(
            "the checkpoint has no weights for {untrained:?} (a VGGT checkpoint?): these modules are untrained, so \
             the Gaussians, dynamic maps, sky and renders are not meaningful; cameras and depth are"
        ));
    }
    if !report.unused.is_empty() {
        tracing::debug!(count = report.unused.len(), "checkpoint tensors not used by this architecture");
    }
    let info = CheckpointInfo {
        path: path.to_path_buf(),
        format: "release".into(),
        architecture: arch_name,
        parameters: burn::module::Module::num_params(&model),
        fresh_modules: fresh,
    };
    Ok(LoadedNetwork { model, config, info, preprocess, assembly, warnings })
}

/// The checkpoint folder of a `step-N` folder, a run's `checkpoints/` folder or a run folder.
fn trainer_checkpoint_dir(path: &Path) -> Result<PathBuf, ReconstructError> {
    if path.join("model.json").is_file() {
        return Ok(path.to_path_buf());
    }
    for root in [path.to_path_buf(), path.join("checkpoints")] {
        if root.join("latest").is_file()
            && let Some(dir) = checkpoint::latest(&root)?
        {
            return Ok(dir);
        }
    }
    Err(ReconstructError::Checkpoint {
        path: path.to_path_buf(),
        detail: "a folder without model.json or a `latest` checkpoint pointer (expected a trainer checkpoint \
                 folder, a run folder, or a .pt/.safetensors file)"
            .into(),
    })
}

/// The architecture `arch` names, the training configuration it came from (if a `.toml`), and its name.
fn read_architecture(arch: &Architecture) -> Result<(ModelConfig, Option<TrainConfig>, String), ReconstructError> {
    match arch {
        Architecture::Preset(name) => Ok((model_config(name)?, None, format!("preset `{name}`"))),
        Architecture::Config(path) if path.extension().is_some_and(|e| e == "toml") => {
            let train = TrainConfig::load(path)?;
            Ok((train.model.architecture()?, Some(train), format!("{}", path.display())))
        }
        Architecture::Config(path) => {
            let config = ModelConfig::from_parity_json(path).map_err(|e| ReconstructError::Input {
                path: path.clone(),
                detail: format!("not a model configuration: {e}"),
            })?;
            Ok((config, None, format!("{}", path.display())))
        }
    }
}
