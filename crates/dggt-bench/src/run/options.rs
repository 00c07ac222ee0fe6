//! What `dggt bench` is asked: the scene, the network, the sweep, the repetitions, the cameras' source, and
//! the optional LPIPS weights and diffusion refiner. Apart from the rest so that callers build a run without
//! reading how it is measured.

use std::path::PathBuf;

use dggt_infer::CameraSource;
use dggt_refine::RefinerSpec;

use crate::knobs::SweepSpec;

/// LPIPS-Alex weight files: the AlexNet backbone and the lpips linear layers (may be one file).
#[derive(Debug, Clone, PartialEq)]
pub struct LpipsFiles {
    pub backbone: PathBuf,
    pub linear: PathBuf,
}

/// Everything a benchmark run is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchOptions {
    /// A scene export (its images are the ground truth).
    pub scene: PathBuf,
    /// A trainer checkpoint (or release file); `None` runs a fresh tiny model seeded with `seed`.
    pub checkpoint: Option<PathBuf>,
    /// Camera ids of the export.
    pub cameras: Vec<usize>,
    /// Target frame positions; default [`crate::frames::default_targets`].
    pub targets: Option<Vec<usize>>,
    pub sweep: SweepSpec,
    /// Timed repetitions per configuration (the median is reported).
    pub repeat: usize,
    /// Untimed runs before them.
    pub warmup: usize,
    /// Where the cameras that place the Gaussians and view the targets come from: the export's, re-expressed
    /// in the first input view's frame (how the tiny model is trained), or the camera head's with targets
    /// interpolated between input views (as `dggt reconstruct` renders).
    pub poses: CameraSource,
    pub lpips: Option<LpipsFiles>,
    pub seed: u64,
    /// Frames per chunk of the dense heads.
    pub chunk_frames: usize,
    /// A diffusion refiner: every measured row's renders are also refined, timed and scored against the truth.
    pub refine: Option<RefinerSpec>,
}

impl BenchOptions {
    /// Defaults for everything but the scene: camera 0, the default sweep, 3 repetitions after 1 warm-up.
    pub fn new(scene: impl Into<PathBuf>) -> Self {
        Self {
            scene: scene.into(),
            checkpoint: None,
            cameras: vec![0],
            targets: None,
            sweep: SweepSpec::default(),
            repeat: 3,
            warmup: 1,
            poses: CameraSource::GroundTruth,
            lpips: None,
            seed: 0,
            chunk_frames: 4,
            refine: None,
        }
    }
}
