//! One training step at scale, as the release fine-tunes DGGT (`configs/dggt-waymo.toml`): the aggregator,
//! camera head and depth head frozen, `N` input frames and `2N` interpolated targets rendered from the
//! predicted cameras (the inputs rendered too), the rendering, opacity, dynamic and lifespan losses, AdamW with
//! clipping. LPIPS is off (it needs weight files); weights are random.
//!
//! The data are a procedural scene ([`dggt_synth`]) written to a scratch folder (at full scale at half the network's
//! input size, enlarged by the loader's preprocessing); every step draws its own
//! sample through the trainer's loader, so the step is the trainer's own ([`Trainer::train_step`]).

use std::collections::BTreeMap;
use std::path::Path;

use burn::tensor::Device;
use dggt_data::ExportVariant;
use dggt_synth::{Sweeps, SynthConfig};
use dggt_train::records::FailureRecord;
use dggt_train::{DepthFlowMaps, Start, TrainConfig, Trainer};

use super::{ComputeOptions, Record, Scale, ScaleSpec, timed};
use crate::error::BenchError;

/// `train-step/{N}+{2N}/f32`.
pub fn train_step_record(options: &ComputeOptions, spec: &ScaleSpec, device: &Device) -> Record {
    let key = format!("train-step/{}+{}/f32", spec.train_inputs, 2 * spec.train_inputs);
    let scratch = match Scratch::new(options) {
        Ok(scratch) => scratch,
        Err(error) => return Record::failed(key, error),
    };
    let mut trainer = match build_trainer(options.scale, spec, scratch.path(), device) {
        Ok(trainer) => trainer,
        Err(error) => return Record::failed(key, error),
    };
    let mut sample_index = 0;
    let mut last_stages = None;
    let record = timed(key, options, device, || {
        let sample = trainer
            .sample(sample_index)
            .map_err(|source| BenchError::Train { doing: "loading a training sample", source: Box::new(source) })?;
        sample_index += 1;
        let metrics = trainer
            .train_step(&[sample], 1.0, DepthFlowMaps::Skip)
            .map_err(|source| BenchError::Train { doing: "a training step", source: Box::new(source) })?;
        if let Some(FailureRecord::Skipped(reason)) = &metrics.failure {
            return Err(BenchError::StepSkipped(reason.to_string()));
        }
        last_stages = metrics.measures.map(|measures| measures.stage_seconds);
        Ok(())
    });
    let views = format!("{} inputs, {} targets", spec.train_inputs, 2 * spec.train_inputs);
    record.with_note(format!(
        "{views} at {}x{}; frozen aggregator, camera and depth heads; LPIPS off; last step's stages (s): {}",
        spec.image.width,
        spec.image.height,
        stage_summary(last_stages.as_ref())
    ))
}

/// `stage_s` of a step's metrics as `name time` pairs.
fn stage_summary(stages: Option<&BTreeMap<String, f64>>) -> String {
    match stages {
        Some(map) => map.iter().map(|(name, seconds)| format!("{name} {seconds:.3}")).collect::<Vec<_>>().join(", "),
        None => "none".into(),
    }
}

/// A folder for the scene and the run: the requested one, or a temporary one removed afterwards.
enum Scratch {
    Given(std::path::PathBuf),
    Temporary(tempfile::TempDir),
}

impl Scratch {
    fn new(options: &ComputeOptions) -> Result<Self, BenchError> {
        match &options.scratch {
            Some(path) => {
                std::fs::create_dir_all(path).map_err(|e| BenchError::file(path, format!("cannot create: {e}")))?;
                Ok(Self::Given(path.clone()))
            }
            None => tempfile::tempdir().map(Self::Temporary).map_err(BenchError::ScratchFolder),
        }
    }

    fn path(&self) -> &Path {
        match self {
            Self::Given(path) => path,
            Self::Temporary(dir) => dir.path(),
        }
    }
}

/// The trainer of the recipe above on a fresh procedural scene under `scratch`.
fn build_trainer(scale: Scale, spec: &ScaleSpec, scratch: &Path, device: &Device) -> Result<Trainer, BenchError> {
    let scene = scratch.join("scene");
    if scene.exists() {
        std::fs::remove_dir_all(&scene).map_err(|e| BenchError::file(&scene, format!("cannot clear: {e}")))?;
    }
    // Full size: half the input size, as a log's larger frames are resized; reduced: the input size.
    let divisor = match scale {
        Scale::Full => 2,
        Scale::Reduced => 1,
    };
    let (width, height) = (spec.image.width / divisor, spec.image.height / divisor);
    let synth = SynthConfig { seed: 0, frames: 20, cameras: 1, width, height };
    dggt_synth::synthesize(&synth, &scene, ExportVariant::Waymo, Sweeps::Skip)
        .map_err(|e| BenchError::file(&scene, format!("writing the procedural scene: {e}")))?;
    let config_path = scratch.join("train-step.toml");
    let text = config_text(scale, spec, &scene, &scratch.join("run"));
    std::fs::write(&config_path, text).map_err(|e| BenchError::file(&config_path, e))?;
    let config = TrainConfig::load(&config_path).map_err(|e| BenchError::file(&config_path, e))?;
    Trainer::new(config, vec![device.clone()], Start::Fresh)
        .map_err(|source| BenchError::Train { doing: "building the trainer", source: Box::new(source) })
}

/// The training configuration of the step (the recipe of `configs/dggt-waymo.toml` without its files).
fn config_text(scale: Scale, spec: &ScaleSpec, scene: &Path, out_dir: &Path) -> String {
    let preset = match scale {
        Scale::Full => "dggt",
        Scale::Reduced => "tiny",
    };
    let n = spec.train_inputs;
    format!(
        r#"[model]
preset = "{preset}"

[data]
scene = "{scene}"
workers = 1

[data.preprocess]
target_width = {width}
patch_size = 14
crop_to_square = false

[sampler]
min_inputs = {n}
max_inputs = {n}
window = 20
targets_per_input = 2
target_margin = 1
cameras = [0]

[render]
cameras = "predicted"
means_gradient = "detached"
render_inputs = true
sky = true

[loss]
rgb_l2 = 1.0
lpips = 0.0
opacity_bce = 0.1
dynamic_bce = 0.05
lifespan_l1 = 0.01

[optim]
lr = 4e-5
frozen = ["aggregator", "camera_head", "depth_head"]
weight_decay = 1e-4
warmup_steps = 0
clip_grad_norm = 1.0
accumulation = 1

[optim.groups]
sky_model = 1e-4

[run]
steps = 1000000
seed = 0
out_dir = "{out}"
checkpoint_every = 1000000
validate_every = 0
"#,
        scene = scene.display(),
        width = spec.image.width,
        out = out_dir.display(),
    )
}
