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

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Tensor};
use dggt_data::Preprocess;
use dggt_model::sky::SkyModel;
use dggt_model::weights::{Coverage, load_checkpoint_with, load_module_from};
use dggt_model::{Dggt, ModelConfig, Preset};
use dggt_scene::AssemblySettings;
use serde::Serialize;

use crate::coverage::check_release_coverage;
use crate::error::InferError;
use crate::settings::TrainedSettings;

/// Where the architecture of a release-format checkpoint comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Architecture {
    /// A model `config.json` (the parity-vector layout) or a training configuration `.toml`.
    Config(PathBuf),
    Preset(Preset),
}

/// The default architecture of release-format checkpoints.
pub const DEFAULT_PRESET: Preset = Preset::Dggt;

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
    /// The input preprocessing the network was trained with, when known: recorded in a trainer checkpoint,
    /// else that of a training `.toml` given as `--config`.
    pub preprocess: Option<Preprocess>,
    /// How targets are assembled and rasterised: as the training `.toml` given as `--config` rendered them
    /// (its `render` section: dynamic blend, `eps2d`, far plane), else as the release does.
    pub assembly: AssemblySettings,
    pub warnings: Vec<String>,
}

impl LoadedNetwork {
    /// The preprocessing to run the network with: at `width` when given, else at the training's width (see
    /// [`Self::preprocess`]), else at the release's 518; always with the network's patch size.
    pub fn input_preprocess(&self, width: Option<u32>) -> Preprocess {
        let mut preprocess = self.preprocess.unwrap_or_default();
        if let Some(width) = width {
            preprocess.target_width = width;
        }
        preprocess.patch_size = self.config.aggregator.patch_size as u32;
        preprocess
    }
}

/// Loads `path` on `device`.
pub fn load_network(
    path: &Path,
    architecture: Option<&Architecture>,
    device: &Device,
) -> Result<LoadedNetwork, InferError> {
    let fail = |detail: String| InferError::Checkpoint { path: path.to_path_buf(), detail };
    if !path.exists() {
        return Err(fail("does not exist".into()));
    }
    let (config_from_arch, trained, arch_name) = match architecture {
        Some(arch) => {
            let (config, trained, name) = read_architecture(arch)?;
            (Some(config), trained, name)
        }
        None => (None, None, String::new()),
    };
    let preprocess = trained.as_ref().map(|t| *t.preprocess());
    let assembly = trained.as_ref().map_or(AssemblySettings::default(), |t| t.render.assembly());
    let mut warnings = Vec::new();
    if path.is_dir() {
        let dir = dggt_checkpoint::checkpoint_dir(path)?;
        let config = dggt_checkpoint::read_model_config(&dir)?;
        if config_from_arch.as_ref().is_some_and(|c| c != &config) {
            warnings
                .push(format!("{} stores its own architecture; the one from {arch_name} is ignored", dir.display()));
        }
        let preprocess = trained_preprocess(&dir, preprocess, &arch_name, &mut warnings)?;
        let model = dggt_checkpoint::load_model(&dir, Dggt::new(&config, device)?)?;
        let info = CheckpointInfo {
            path: dir.clone(),
            format: "trainer".into(),
            architecture: format!("{}", dir.join(dggt_checkpoint::MODEL_CONFIG_FILE).display()),
            parameters: model.num_params(),
            fresh_modules: Vec::new(),
        };
        return Ok(LoadedNetwork { model, config, info, preprocess, assembly, warnings });
    }

    let (config, arch_name) = match config_from_arch {
        Some(config) => (config, arch_name),
        None => (DEFAULT_PRESET.config(), format!("preset `{DEFAULT_PRESET}`")),
    };
    let mut model = Dggt::new(&config, device)?;
    if let Some(sky) = &config.sky_model {
        model.sky_model = Some(SkyModel::initialised(sky, device));
    }
    let report = load_checkpoint_with(&mut model, path, Coverage::Partial).map_err(|e| match e {
        dggt_model::ModelError::WeightsFile { message, .. } => fail(format!("cannot be read: {message}")),
        dggt_model::ModelError::Safetensors(error) => fail(format!("cannot be read: {error}")),
        other => fail(format!("does not fit the architecture of {arch_name}: {other}")),
    })?;
    let fresh = check_release_coverage(&report, &arch_name, &mut warnings)
        .map_err(|coverage| InferError::ReleaseCoverage { path: path.to_path_buf(), coverage })?;
    let info = CheckpointInfo {
        path: path.to_path_buf(),
        format: "release".into(),
        architecture: arch_name,
        parameters: model.num_params(),
        fresh_modules: fresh,
    };
    Ok(LoadedNetwork { model, config, info, preprocess, assembly, warnings })
}

/// The input preprocessing of the trainer checkpoint `dir`: the one it records, else `configured` (a training
/// `.toml` given as `--config`), else none (the default applies), with a warning where that is a guess.
fn trained_preprocess(
    dir: &Path,
    configured: Option<Preprocess>,
    arch_name: &str,
    warnings: &mut Vec<String>,
) -> Result<Option<Preprocess>, InferError> {
    let recorded = dggt_checkpoint::read_preprocess(dir)?;
    match (recorded, configured) {
        (Some(recorded), Some(configured)) if configured != recorded => warnings.push(format!(
            "{} records the preprocessing it was trained with; the one from {arch_name} is ignored",
            dir.display()
        )),
        (None, None) => warnings.push(format!(
            "{} does not record the input preprocessing it was trained with (a checkpoint of an older version): the \
             default width {} applies unless --width (or a training --config) is given",
            dir.display(),
            Preprocess::default().target_width
        )),
        _ => {}
    }
    Ok(recorded.or(configured))
}

/// The architecture `arch` names, the training settings it came from (if a `.toml`), and its name.
fn read_architecture(arch: &Architecture) -> Result<(ModelConfig, Option<TrainedSettings>, String), InferError> {
    match arch {
        Architecture::Preset(preset) => Ok((preset.config(), None, format!("preset `{preset}`"))),
        Architecture::Config(path) if path.extension().is_some_and(|e| e == "toml") => {
            let trained = TrainedSettings::load(path)?;
            Ok((trained.model.architecture(), Some(trained), format!("{}", path.display())))
        }
        Architecture::Config(path) => {
            let config = ModelConfig::from_parity_json(path).map_err(|e| InferError::Input {
                path: path.clone(),
                detail: format!("not a model configuration: {e}"),
            })?;
            Ok((config, None, format!("{}", path.display())))
        }
    }
}

/// A starting checkpoint and the parameters it may lack: a release file (`.pt`, `.pth`, `.safetensors`, the
/// release's key names) or one of this project's trainer checkpoints (a `step-N` folder, a run's `checkpoints/`
/// folder or the run folder: the network inference would use, its weight average where the run kept one), whose
/// parameters are carried over by module path into a network that may add modules (a flow head).
#[derive(Debug, Clone, Copy)]
pub struct StartingWeights<'a> {
    pub path: &'a Path,
    /// Glob patterns over module paths (`gs_head.*`) of parameters that start fresh when the file lacks them.
    pub may_lack: &'a [String],
}

/// A fresh network drawn from `seed`: random layers, the sky model's fixed buffers, then the starting checkpoint
/// when given. The draw takes its turn with every other seeded draw of the process ([`dggt_model::seeded`]), so
/// the same seed gives the same weights whatever else runs. A parameter the checkpoint lacks is an error naming
/// it unless `may_lack` allows it; tensors of mismatched shape are an error naming every one; tensors the network
/// does not use are reported by name.
pub fn fresh_model(
    config: &ModelConfig,
    init: Option<StartingWeights<'_>>,
    seed: u64,
    device: &Device,
) -> Result<Dggt, InferError> {
    // A trained network is read before the seeded draw, so that the draw is the same whatever the source.
    let source = init.map(|init| StartingSource::open(init.path, device)).transpose()?;
    dggt_model::seeded::with_seed(device, seed, || {
        let mut model = Dggt::new(config, device)?;
        if let Some(sky) = &config.sky_model {
            model.sky_model = Some(SkyModel::initialised(sky, device));
        }
        // Loaded before the fresh parameters are drawn, so that a wrong file fails before the network is allocated.
        if let (Some(init), Some(source)) = (init, &source) {
            apply_starting_weights(&mut model, init, source)?;
        }
        materialise(&model);
        Ok(model)
    })
}

/// Where starting weights are read from.
enum StartingSource {
    /// A release-format file, read as it is applied.
    ReleaseFile,
    /// A trainer checkpoint's network, loaded whole.
    Trained(Box<Dggt>),
}

impl StartingSource {
    /// A folder is a trainer checkpoint (verified, its own architecture); anything else a release-format file.
    fn open(path: &Path, device: &Device) -> Result<Self, InferError> {
        if !path.is_dir() {
            return Ok(Self::ReleaseFile);
        }
        let dir = dggt_checkpoint::checkpoint_dir(path)?;
        let blank = Dggt::new(&dggt_checkpoint::read_model_config(&dir)?, device)?;
        Ok(Self::Trained(Box::new(dggt_checkpoint::load_model(&dir, blank)?)))
    }
}

/// Loads `init` over `model`, refusing it when it lacks what `may_lack` does not allow.
fn apply_starting_weights(
    model: &mut Dggt,
    init: StartingWeights<'_>,
    source: &StartingSource,
) -> Result<(), InferError> {
    let report = match source {
        StartingSource::ReleaseFile => load_checkpoint_with(model, init.path, Coverage::Partial)?,
        StartingSource::Trained(trained) => load_module_from(model, trained.as_ref(), Coverage::Partial)
            .map_err(|e| InferError::checkpoint(init.path, e))?,
    };
    check_coverage(init, &report)?;
    if !report.unused.is_empty() {
        tracing::warn!(checkpoint = %init.path.display(), unused = ?report.unused, "tensors the network does not use");
    }
    tracing::info!(
        checkpoint = %init.path.display(),
        applied = report.applied.len(),
        fresh = report.missing.len(),
        unused = report.unused.len(),
        "starting weights loaded"
    );
    Ok(())
}

/// Every parameter the checkpoint lacks must match one of the allowed patterns.
fn check_coverage(init: StartingWeights<'_>, report: &dggt_model::weights::LoadReport) -> Result<(), InferError> {
    let patterns = init
        .may_lack
        .iter()
        .map(|p| {
            glob::Pattern::new(p).map_err(|source| InferError::BadPattern {
                setting: "model.init_may_lack",
                pattern: p.clone(),
                source,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let lacking: Vec<&String> =
        report.missing.iter().filter(|name| !patterns.iter().any(|p| p.matches(name))).collect();
    if lacking.is_empty() {
        return Ok(());
    }
    let shown: Vec<&str> = lacking.iter().take(20).map(|s| s.as_str()).collect();
    Err(InferError::checkpoint(
        init.path,
        format!(
            "lacks {} parameter(s) the network needs and model.init_may_lack does not allow ({} applied): {}{}",
            lacking.len(),
            report.applied.len(),
            shown.join(", "),
            if lacking.len() > shown.len() { ", ..." } else { "" }
        ),
    ))
}

/// Initialises every lazily created parameter now, in visiting order, so that the starting weights depend on
/// the seed alone and not on which thread or operation first reads a parameter (data-parallel threads would
/// otherwise draw them in a racy order).
fn materialise(model: &Dggt) {
    struct Touch;
    impl ModuleVisitor for Touch {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let _ = param.val();
        }
    }
    model.visit(&mut Touch);
}
