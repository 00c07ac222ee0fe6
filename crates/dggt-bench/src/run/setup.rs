//! What the sweep loads once before its first row: the scene's frame plan and prepared views, the network
//! (and its copies cast to other precisions), the LPIPS network, the refiner, and the ground truth at the
//! reference size. Every row borrows it.

use std::collections::HashMap;

use burn::tensor::Device;
use dggt_data::{PreparedView, Preprocess, Scene, prepare_view};
use dggt_geom::{ImageSize, PixelConvention};
use dggt_infer::{fresh_model, load_network};
use dggt_losses::{Lpips, LpipsKind};
use dggt_model::{Dggt, ModelConfig};
use dggt_refine::Refiner;

use super::options::BenchOptions;
use crate::error::BenchError;
use crate::frames::{FramePlan, plan_frames};
use crate::knobs::{Configuration, Precision};
use crate::precision::{PrecisionUnsupported, cast_model};

/// The network and what its architecture implies for preprocessing.
pub(super) struct Network {
    model: Dggt,
    patch_size: u32,
    crop_to_square: bool,
    pub(super) description: String,
    pub(super) trained: bool,
}

fn network(options: &BenchOptions, device: &Device) -> Result<(Network, Vec<String>), BenchError> {
    match &options.checkpoint {
        Some(path) => {
            let loaded = load_network(path, None, device)?;
            let preprocess = loaded.preprocess.unwrap_or_default();
            let network = Network {
                patch_size: loaded.config.aggregator.patch_size as u32,
                crop_to_square: preprocess.crop_to_square,
                description: format!("{} ({} parameters)", loaded.info.path.display(), loaded.info.parameters),
                model: loaded.model,
                trained: true,
            };
            Ok((network, loaded.warnings))
        }
        None => {
            let config = fresh_tiny_config();
            let model = fresh_model(&config, None, options.seed, device)?;
            let network = Network {
                patch_size: config.aggregator.patch_size as u32,
                crop_to_square: true,
                description: format!("a fresh tiny model (untrained, seed {})", options.seed),
                model,
                trained: false,
            };
            let note = "no checkpoint: the network is a fresh tiny model with random weights, so the error \
                        against ground truth is meaningless; only the error against the exact render says what a \
                        shortcut costs";
            Ok((network, vec![note.into()]))
        }
    }
}

/// The tiny architecture as `configs/tiny-overfit.toml` trains it: colour skip on, pixel-centred unprojection.
pub fn fresh_tiny_config() -> ModelConfig {
    let mut config = ModelConfig::tiny();
    if let Some(gs) = &mut config.gs_head {
        gs.color_skip = true;
        gs.unproject_at = PixelConvention::Centred;
    }
    config
}

/// Prepared views of the scene per width, decoded once.
pub(super) struct ViewCache<'a> {
    scene: &'a Scene,
    patch_size: u32,
    crop_to_square: bool,
    views: HashMap<(u32, usize, usize), PreparedView>,
}

impl ViewCache<'_> {
    pub(super) fn get(&mut self, width: u32, frame: usize, camera: usize) -> Result<&PreparedView, BenchError> {
        let key = (width, frame, camera);
        if !self.views.contains_key(&key) {
            let preprocess =
                Preprocess { target_width: width, patch_size: self.patch_size, crop_to_square: self.crop_to_square };
            let view = prepare_view(self.scene, frame, camera, &preprocess)?;
            self.views.insert(key, view);
        }
        Ok(&self.views[&key])
    }
}

/// One target view: scene frame position, camera position, and `[H, W, 3]` images at the reference size.
pub(super) struct TargetImages {
    pub(super) frame: usize,
    pub(super) camera: usize,
    pub(super) truth: Vec<f32>,
}

/// The loaded scene and network that every configuration runs on.
pub(super) struct Runner<'a> {
    pub(super) options: &'a BenchOptions,
    pub(super) device: &'a Device,
    pub(super) scene: &'a Scene,
    pub(super) plan: FramePlan,
    pub(super) network: Network,
    cast_models: HashMap<Precision, Dggt>,
    pub(super) cache: ViewCache<'a>,
}

impl Runner<'_> {
    pub(super) fn model(&mut self, precision: Precision) -> &Dggt {
        if precision == Precision::F32 {
            return &self.network.model;
        }
        let base = &self.network.model;
        self.cast_models.entry(precision).or_insert_with(|| cast_model(base, precision))
    }
}

/// Everything the rows share: the runner, the ground truth at the reference size, the scoring and refining
/// networks, and what earlier rows found out (the precisions the backend supports, the exact renders).
pub(super) struct Sweep<'a> {
    pub(super) runner: Runner<'a>,
    pub(super) targets: Vec<TargetImages>,
    /// The size every error is measured at.
    pub(super) reference_size: ImageSize,
    pub(super) lpips: Option<Lpips>,
    pub(super) refiner: Option<Refiner>,
    pub(super) support: HashMap<Precision, Result<(), PrecisionUnsupported>>,
    /// The exact reference's renders at the reference size, once it has run.
    pub(super) exact: Option<Vec<Vec<f32>>>,
}

/// Loads what the sweep of `configurations` over `scene` needs; with it, the notes the network leaves.
pub(super) fn set_up<'a>(
    options: &'a BenchOptions,
    device: &'a Device,
    scene: &'a Scene,
    configurations: &[Configuration],
) -> Result<(Sweep<'a>, Vec<String>), BenchError> {
    let plan = plan_frames(scene.frames.len(), options.targets.as_deref())?;
    let (network, notes) = network(options, device)?;
    let patch = network.patch_size;
    if let Some(bad) = configurations.iter().map(|c| c.knobs.width).find(|w| !w.is_multiple_of(patch)) {
        return Err(BenchError::setting("width", format!("{bad} px is not a multiple of the {patch}-pixel patch")));
    }
    let lpips = match &options.lpips {
        Some(files) => Some(Lpips::load(LpipsKind::Alex, &files.backbone, &files.linear, device)?),
        None => None,
    };
    let refiner = match &options.refine {
        Some(spec) => Some(
            spec.load(device)
                .map_err(|source| BenchError::Refine { doing: "loading the refiner", source: Box::new(source) })?
                .0,
        ),
        None => None,
    };
    let cache = ViewCache { scene, patch_size: patch, crop_to_square: network.crop_to_square, views: HashMap::new() };
    let mut runner = Runner { options, device, scene, plan, network, cast_models: HashMap::new(), cache };

    // Ground truth at the reference size.
    let reference_width = options.sweep.baseline.width;
    let mut targets = Vec::new();
    for &frame in &runner.plan.targets.clone() {
        for camera in 0..scene.cameras.len() {
            let view = runner.cache.get(reference_width, frame, camera)?;
            targets.push(TargetImages { frame, camera, truth: view.image.interleaved() });
        }
    }
    let reference_size = runner.cache.get(reference_width, runner.plan.targets[0], 0)?.image.size;
    let sweep = Sweep { runner, targets, reference_size, lpips, refiner, support: HashMap::new(), exact: None };
    Ok((sweep, notes))
}
