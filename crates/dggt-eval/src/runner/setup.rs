//! What an evaluation is asked and what it opens once, before any scene is evaluated: the options, every scene
//! export checked for the protocol's cameras and window, LPIPS, the motion source of the loaded network, and
//! the context that every scene is evaluated with.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_data::{Preprocess, Scene, open_scene};
use dggt_infer::{Architecture, CameraSource, LoadedNetwork};
use dggt_losses::{Lpips, LpipsKind};
use dggt_refine::{Refiner, RefinerSpec};
use dggt_scene::DynamicMotion;

use crate::error::EvalError;
use crate::grid::CellSampling;
use crate::protocol::Protocol;
use crate::sources::CropImages;

/// The two files of LPIPS-Alex: the lpips package's linear layers and the AlexNet features.
#[derive(Debug, Clone, PartialEq)]
pub struct LpipsWeights {
    /// `alex.pth` of the lpips package (or a full LPIPS state dict, or safetensors with its names).
    pub linear: PathBuf,
    /// AlexNet `features` weights (torchvision or lpips names; may be the same file as `linear`).
    pub alexnet: PathBuf,
}

/// Everything an evaluation is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalOptions {
    /// Scene exports, each evaluated on the same window.
    pub scenes: Vec<PathBuf>,
    pub checkpoint: PathBuf,
    /// Architecture of `.pt` / `.safetensors` checkpoints (default: the `dggt` preset).
    pub architecture: Option<Architecture>,
    pub protocol: Protocol,
    /// Network input width (a multiple of 14); default: the width the network was trained at (recorded in a
    /// trainer checkpoint, or the `--config` training file's), else 518.
    pub width: Option<u32>,
    /// Frames per chunk of the dense heads.
    pub chunk_frames: usize,
    /// LPIPS-Alex weights; without them LPIPS is not computed.
    pub lpips: Option<LpipsWeights>,
    /// A diffusion refiner: every render is also refined and scored again (image metrics only; depth and
    /// motion come from the Gaussians). Its time counts in the `render` stage.
    pub refine: Option<RefinerSpec>,
    /// Output folder of `eval.json` and `eval.md`.
    pub out: PathBuf,
    /// Whether crops of the moving objects under every image source are written to `out/crops/`.
    pub crops: CropImages,
    /// Where the cameras come from: the camera head's (the paper's unposed protocol) or the export's.
    pub poses: CameraSource,
    /// How rendered depth and flow are read at the lidar cells.
    pub cell_sampling: CellSampling,
}

impl EvalOptions {
    /// The paper protocol with defaults for everything but the paths.
    pub fn new(scenes: Vec<PathBuf>, checkpoint: impl Into<PathBuf>, out: impl Into<PathBuf>) -> Self {
        Self {
            scenes,
            checkpoint: checkpoint.into(),
            architecture: None,
            protocol: Protocol::paper(),
            width: None,
            chunk_frames: 4,
            lpips: None,
            refine: None,
            out: out.into(),
            crops: CropImages::Skip,
            poses: CameraSource::Predicted,
            cell_sampling: CellSampling::Bilinear,
        }
    }
}

/// What every scene of an evaluation is evaluated with.
#[derive(Clone, Copy)]
pub(super) struct SceneContext<'a> {
    pub(super) options: &'a EvalOptions,
    pub(super) network: &'a LoadedNetwork,
    pub(super) preprocess: Preprocess,
    pub(super) lpips: Option<&'a Lpips>,
    pub(super) refiner: Option<&'a Refiner>,
    pub(super) motion: DynamicMotion,
    pub(super) device: &'a Device,
}

/// Checks that `root` is a scene export with the protocol's cameras and window; returns the window.
pub fn open_window(root: &Path, protocol: &Protocol) -> Result<Scene, EvalError> {
    if !root.is_dir() {
        return Err(EvalError::scene(root, "not found (expected a scene export folder)"));
    }
    if !root.join("images").is_dir() || !root.join("intrinsics").is_dir() {
        return Err(EvalError::scene(root, "not a scene export (expected images/ and intrinsics/ in it)"));
    }
    let present = export_cameras(root);
    for &camera in &protocol.cameras {
        if !present.contains(&camera) {
            return Err(EvalError::scene(
                root,
                format!("has no camera {camera} (no intrinsics/{camera}.txt); its cameras are {present:?}"),
            ));
        }
    }
    let all = open_scene(root, None, Some(protocol.cameras.clone()))?;
    let frames: Vec<usize> = all.frames.iter().map(|f| f.index).collect();
    protocol.check_frames(root, &frames)?;
    Ok(open_scene(root, Some(protocol.window()), Some(protocol.cameras.clone()))?)
}

/// Camera ids with an `intrinsics/{id}.txt`, ascending.
fn export_cameras(root: &Path) -> Vec<usize> {
    let mut ids: Vec<usize> = std::fs::read_dir(root.join("intrinsics"))
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .filter_map(|e| {
                    let name = e.file_name().to_string_lossy().into_owned();
                    name.strip_suffix(".txt").and_then(|stem| stem.parse().ok())
                })
                .collect()
        })
        .unwrap_or_default();
    ids.sort_unstable();
    ids
}

/// LPIPS-Alex from the options' weights, or without them none and the report's note why.
pub(super) fn load_lpips(options: &EvalOptions, device: &Device) -> Result<(Option<Lpips>, Option<String>), EvalError> {
    Ok(match &options.lpips {
        Some(weights) => (Some(Lpips::load(LpipsKind::Alex, &weights.alexnet, &weights.linear, device)?), None),
        None => (None, Some("not computed: no weights given (--lpips-weights alex.pth --alexnet FILE)".to_string())),
    })
}

/// The motion source that the network's renders move with.
pub(super) fn motion_source(network: &LoadedNetwork) -> DynamicMotion {
    network.assembly.dynamic_motion.in_effect(network.config.predicts_motion())
}
