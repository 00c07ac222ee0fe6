//! The sweep: loads the scene and the network once, then measures every configuration: stage times (median of
//! `repeat` runs after `warmup` runs), Gaussians kept, and the error of the target renders against the exact
//! render and against the export's images.
//!
//! Conventions: the world is the first input view's camera frame (ground-truth poses re-expressed in it, as in
//! training, or the camera head's prediction); times in milliseconds; images `[H, W, 3]` RGB in `[0, 1]`
//! (renders clamped to it before any metric, as they are saved); every error is measured at the reference
//! resolution (the baseline width): a render of another size is resized to it, full frame to full frame (each
//! preprocessed size covers the original image's whole field of view), with `image`'s triangle filter
//! (bilinear, widened to an antialiasing filter when shrinking).

use std::collections::HashMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::{PreparedView, Preprocess, Scene, prepare_view};
use dggt_geom::{ImageSize, PixelConvention, PosedCamera};
use dggt_infer::{
    CameraSource, InputCameras, MotionPath, SceneOptions, SkyChoice, ViewSlot, fresh_model, input_views, load_network,
};
use dggt_losses::{Lpips, LpipsKind};
use dggt_metrics::ImageShape;
use dggt_model::host::host_f32;
use dggt_model::{Dggt, ModelConfig};
use dggt_refine::{Latent, ReferenceView, Refiner, RefinerSpec, frame_from_interleaved, frame_to_interleaved};
use dggt_scene::{AssemblyCounts, AssemblySettings, TargetView, Timeline, nearest_in_time};

use crate::error::BenchError;
use crate::frames::{FramePlan, plan_frames};
use crate::knobs::{Configuration, Culling, Knobs, Precision, SweepSpec, Varied};
use crate::pareto::pareto_front;
use crate::precision::{PrecisionUnsupported, cast_model, panic_message, precision_support};
use crate::stages::{self, settle};

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

/// Median stage times of one configuration, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimes {
    /// Aggregator (patch embedding and alternating attention), timed in a run of its own.
    pub backbone_ms: f64,
    /// Camera head and dense heads (depth, dynamic, Gaussian): a run of the aggregator and the heads together,
    /// less `backbone_ms`.
    pub heads_ms: f64,
    /// Cameras, per-pixel Gaussians, sky Gaussians, and per target view the lifespan fade and culling.
    pub assembly_ms: f64,
    /// Rasterising every target view (foreground and sky), compositing, reading the images back.
    pub raster_ms: f64,
    /// Median of the per-repetition sums of the four.
    pub total_ms: f64,
}

/// Mean over the target views.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorMetrics {
    /// Infinite where the images are identical.
    pub psnr_db: f64,
    pub ssim: f64,
    /// LPIPS-Alex when its weights were given.
    pub lpips: Option<f64>,
}

/// What the row's shortcuts ([`Skips`](crate::knobs::Skips)) left out in its last repetition.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SkipCounts {
    /// Input frames whose motion head did not run.
    pub motion_frames: usize,
    /// Target views rendered without their sky (when there is a sky model).
    pub sky_views: usize,
}

/// One measured configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredRow {
    pub configuration: Configuration,
    /// The network's input size.
    pub size: ImageSize,
    /// Input frame positions.
    pub input_frames: Vec<usize>,
    pub times: StageTimes,
    /// Mean over target views of the Gaussians reaching the rasteriser (foreground; the sky's are apart).
    pub gaussians_kept: f64,
    /// Mean over target views of the candidates before culling.
    pub gaussian_candidates: f64,
    pub sky_gaussians: usize,
    pub skipped: SkipCounts,
    pub vs_exact: ErrorMetrics,
    pub vs_truth: ErrorMetrics,
    pub pareto_vs_exact: bool,
    pub pareto_vs_truth: bool,
    /// The renders after the diffusion refiner, when one was given.
    pub refined: Option<RefinedRow>,
}

/// A row's renders refined: the time it took and the error against the ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefinedRow {
    /// Median over the repetitions of refining every target view (one frame at a time), milliseconds.
    pub refine_ms: f64,
    pub vs_truth: ErrorMetrics,
}

/// A configuration's outcome.
#[derive(Debug, Clone, PartialEq)]
pub enum RowOutcome {
    Measured(MeasuredRow),
    /// Not run: the backend lacks the precision, the scene has too few frames, or the run failed; the reason.
    Skipped {
        configuration: Configuration,
        reason: String,
    },
}

impl RowOutcome {
    pub fn configuration(&self) -> &Configuration {
        match self {
            Self::Measured(row) => &row.configuration,
            Self::Skipped { configuration, .. } => configuration,
        }
    }

    pub fn measured(&self) -> Option<&MeasuredRow> {
        match self {
            Self::Measured(row) => Some(row),
            Self::Skipped { .. } => None,
        }
    }
}

/// The result of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchReport {
    /// One per configuration, in sweep order (the exact reference first).
    pub rows: Vec<RowOutcome>,
    /// Facts a reader needs: what the knobs mean here, what is not swept, what was skipped and why.
    pub notes: Vec<String>,
    /// The size every error is measured at.
    pub reference_size: ImageSize,
    pub device: String,
    /// The checkpoint, or a description of the fresh model.
    pub network: String,
    /// `false` for a fresh model: its ground-truth error means nothing.
    pub truth_meaningful: bool,
    pub target_frames: Vec<usize>,
    pub cameras: Vec<usize>,
    pub repeat: usize,
    pub warmup: usize,
}

/// The network and what its architecture implies for preprocessing.
struct Network {
    model: Dggt,
    patch_size: u32,
    crop_to_square: bool,
    description: String,
    trained: bool,
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
struct ViewCache<'a> {
    scene: &'a Scene,
    patch_size: u32,
    crop_to_square: bool,
    views: HashMap<(u32, usize, usize), PreparedView>,
}

impl ViewCache<'_> {
    fn get(&mut self, width: u32, frame: usize, camera: usize) -> Result<&PreparedView, BenchError> {
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
struct TargetImages {
    frame: usize,
    camera: usize,
    truth: Vec<f32>,
}

/// What one configuration's last repetition rendered, and its timings.
struct RowRun {
    size: ImageSize,
    input_frames: Vec<usize>,
    times: StageTimes,
    gaussians_kept: f64,
    gaussian_candidates: f64,
    sky_gaussians: usize,
    skipped: SkipCounts,
    /// Per target view, `[H, W, 3]` at the row's size, clamped to `[0, 1]`.
    renders: Vec<Vec<f32>>,
    /// Per target view, the refiner's reference view `[H, W, 3]` when it takes one (see
    /// [`RowSetup::references`]).
    references: Vec<Vec<f32>>,
}

struct Runner<'a> {
    options: &'a BenchOptions,
    device: &'a Device,
    scene: &'a Scene,
    plan: FramePlan,
    network: Network,
    cast_models: HashMap<Precision, Dggt>,
    cache: ViewCache<'a>,
}

/// Runs the sweep of `options` on `device`.
pub fn run_bench(options: &BenchOptions, device: &Device) -> Result<BenchReport, BenchError> {
    options.sweep.validate()?;
    if options.repeat == 0 {
        return Err(BenchError::setting("--repeat", "must be at least 1"));
    }
    if options.cameras.is_empty() {
        return Err(BenchError::setting("--cameras", "no camera given"));
    }
    let scene = dggt_data::open_scene(&options.scene, None, Some(options.cameras.clone()))?;
    let plan = plan_frames(scene.frames.len(), options.targets.as_deref())?;
    let (network, mut notes) = network(options, device)?;
    let configurations = options.sweep.configurations();
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
    let cache =
        ViewCache { scene: &scene, patch_size: patch, crop_to_square: network.crop_to_square, views: HashMap::new() };
    let truth_meaningful = network.trained;
    let network_description = network.description.clone();
    let mut runner = Runner { options, device, scene: &scene, plan, network, cast_models: HashMap::new(), cache };

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

    let mut support: HashMap<Precision, Result<(), PrecisionUnsupported>> = HashMap::new();
    let mut reference: Option<Vec<Vec<f32>>> = None;
    let mut rows = Vec::new();
    for configuration in configurations {
        let knobs = configuration.knobs;
        let supported = support.entry(knobs.precision).or_insert_with(|| precision_support(device, knobs.precision));
        if let Err(reason) = supported.clone() {
            rows.push(RowOutcome::Skipped { configuration, reason: reason.to_string() });
            continue;
        }
        let inputs = match runner.plan.inputs(knobs.input_frames) {
            Ok(inputs) => inputs,
            Err(reason) => {
                rows.push(RowOutcome::Skipped { configuration, reason: reason.to_string() });
                continue;
            }
        };
        tracing::info!("measuring {} ({})", knobs.label(), configuration.varied.name());
        let run = match measure(&mut runner, &configuration, &inputs, &targets)? {
            Ok(run) => run,
            Err(reason) => {
                rows.push(RowOutcome::Skipped { configuration, reason });
                continue;
            }
        };
        let at_reference: Vec<Vec<f32>> =
            run.renders.iter().map(|image| resize_rgb(image, run.size, reference_size)).collect();
        if configuration.varied == Varied::Reference {
            reference = Some(at_reference.clone());
        }
        let exact = reference.as_ref().ok_or_else(|| BenchError::Missing("sweep: the exact reference runs first"))?;
        let vs_exact = compare(&at_reference, exact, reference_size, lpips.as_ref(), device)?;
        let truth: Vec<Vec<f32>> = targets.iter().map(|t| t.truth.clone()).collect();
        let vs_truth = compare(&at_reference, &truth, reference_size, lpips.as_ref(), device)?;
        let refined = match (&refiner, &options.refine) {
            (Some(refiner), Some(spec)) => {
                let (refine_ms, images) = refine_renders(refiner, spec.latent, &run, options.repeat, device)?;
                let at_reference: Vec<Vec<f32>> =
                    images.iter().map(|image| resize_rgb(image, run.size, reference_size)).collect();
                let vs_truth = compare(&at_reference, &truth, reference_size, lpips.as_ref(), device)?;
                Some(RefinedRow { refine_ms, vs_truth })
            }
            _ => None,
        };
        rows.push(RowOutcome::Measured(MeasuredRow {
            configuration,
            size: run.size,
            input_frames: run.input_frames,
            times: run.times,
            gaussians_kept: run.gaussians_kept,
            gaussian_candidates: run.gaussian_candidates,
            sky_gaussians: run.sky_gaussians,
            skipped: run.skipped,
            vs_exact,
            vs_truth,
            pareto_vs_exact: false,
            pareto_vs_truth: false,
            refined,
        }));
    }
    mark_pareto(&mut rows);

    notes.extend(standing_notes(options, reference_size));
    for row in &rows {
        if let RowOutcome::Skipped { configuration, reason } = row {
            notes.push(format!("skipped {}: {reason}", configuration.knobs.label()));
        }
    }
    Ok(BenchReport {
        rows,
        notes,
        reference_size,
        device: format!("{device:?}"),
        network: network_description,
        truth_meaningful,
        target_frames: runner.plan.targets.clone(),
        cameras: options.cameras.clone(),
        repeat: options.repeat,
        warmup: options.warmup,
    })
}

/// Runs one configuration, a panic caught: the run, or why the row is skipped. A failure of the exact reference
/// is an error, since every other row is measured against it.
fn measure(
    runner: &mut Runner<'_>,
    configuration: &Configuration,
    inputs: &[usize],
    targets: &[TargetImages],
) -> Result<Result<RowRun, String>, BenchError> {
    let knobs = configuration.knobs;
    let is_reference = configuration.varied == Varied::Reference;
    match catch_unwind(AssertUnwindSafe(|| runner.run(&knobs, inputs, targets))) {
        Ok(Ok(run)) => Ok(Ok(run)),
        Ok(Err(error)) if is_reference => Err(error),
        Ok(Err(error)) => Ok(Err(match knobs.precision {
            Precision::F32 => format!("failed: {error}"),
            reduced => format!("failed: the network runs in {reduced} but its outputs are unusable: {error}"),
        })),
        Err(panic) => {
            let message = panic_message(&*panic).split_whitespace().collect::<Vec<_>>().join(" ");
            if is_reference {
                return Err(BenchError::Panicked { doing: "the exact reference render", message });
            }
            Ok(Err(format!("failed: {message}")))
        }
    }
}

/// Marks the Pareto fronts of total time against PSNR vs exact and vs truth.
fn mark_pareto(rows: &mut [RowOutcome]) {
    let measured: Vec<usize> = (0..rows.len()).filter(|&i| rows[i].measured().is_some()).collect();
    let points = |quality: fn(&MeasuredRow) -> f64, rows: &[RowOutcome]| -> Vec<(f64, f64)> {
        measured.iter().filter_map(|&i| rows[i].measured().map(|r| (r.times.total_ms, quality(r)))).collect()
    };
    let exact = pareto_front(&points(|r| r.vs_exact.psnr_db, rows));
    let truth = pareto_front(&points(|r| r.vs_truth.psnr_db, rows));
    for (k, &i) in measured.iter().enumerate() {
        if let RowOutcome::Measured(row) = &mut rows[i] {
            row.pareto_vs_exact = exact[k];
            row.pareto_vs_truth = truth[k];
        }
    }
}

fn standing_notes(options: &BenchOptions, reference_size: ImageSize) -> Vec<String> {
    let base = options.sweep.baseline;
    let refinement = match &options.refine {
        None => "refinement: no diffusion refiner given (--refine MODEL_DIR): renders are scored unrefined".into(),
        Some(spec) => format!(
            "refinement: every row's target renders also refined by {} one frame at a time at the row's render \
             size (refine_ms: median of the repetitions, not in total_ms), scored against the truth at the \
             reference size",
            spec.describe()
        ),
    };
    vec![
        refinement,
        format!(
            "culling: the assembly has one opacity threshold (AssemblySettings::min_opacity), compared with each \
             Gaussian's opacity after the lifespan fade at the target time, so it is also the lifespan cutoff; there \
             is no separate lifespan knob. Every row but the exact one also drops Gaussians whose footprint misses \
             the image. The rasteriser itself skips alpha below 1/255 (dggt_scene::MIN_OPACITY), so a 1/255 \
             threshold only removes work"
        ),
        format!(
            "precision: applies to the network (aggregator and heads; parameters and input cast, outputs cast back \
             to f32); the sky model, assembly and rasteriser always compute in f32"
        ),
        format!(
            "vs exact: each row's target renders against the exact render (width {} px, {} input frames, culling \
             off, f32, sky {}), all at {}; renders of other sizes are resized to it full frame to full frame with \
             a triangle filter (bilinear, antialiased when shrinking); PSNR is infinite where they are identical",
            base.width,
            base.input_frames,
            if base.sky == SkyChoice::Render { "on" } else { "off" },
            reference_size
        ),
        format!(
            "vs truth: against the export's images of the target frames, preprocessed to {reference_size}; cameras \
             from {}",
            match options.poses {
                CameraSource::GroundTruth => "the export's poses (relative to the first input view)",
                CameraSource::Predicted => "the camera head (targets interpolated between input views)",
            }
        ),
        format!(
            "times: median of {} repetitions after {} warm-up runs; image decoding and preprocessing are not \
             timed",
            options.repeat, options.warmup
        ),
    ]
}

impl Runner<'_> {
    fn model(&mut self, precision: Precision) -> &Dggt {
        if precision == Precision::F32 {
            return &self.network.model;
        }
        let base = &self.network.model;
        self.cast_models.entry(precision).or_insert_with(|| cast_model(base, precision))
    }

    /// Measures one configuration with the given input frames.
    fn run(&mut self, knobs: &Knobs, inputs: &[usize], targets: &[TargetImages]) -> Result<RowRun, BenchError> {
        let setup = self.prepare(knobs, inputs, targets)?;
        let model = self.model(knobs.precision).clone();
        let mut samples: Vec<[f64; 4]> = Vec::new();
        let mut last = None;
        for repetition in 0..self.options.warmup + self.options.repeat {
            let (times, outputs) = self.repetition(&model, &setup)?;
            if repetition >= self.options.warmup {
                samples.push(times);
            }
            last = Some(outputs);
        }
        let last = last.ok_or_else(|| BenchError::setting("--repeat", "no run"))?;
        let median_of = |k: usize| median(samples.iter().map(|s| s[k]).collect());
        let times = StageTimes {
            backbone_ms: median_of(0),
            heads_ms: median_of(1),
            assembly_ms: median_of(2),
            raster_ms: median_of(3),
            total_ms: median(samples.iter().map(|s| s.iter().sum()).collect()),
        };
        let views = last.counts.len().max(1) as f64;
        Ok(RowRun {
            size: setup.size,
            input_frames: inputs.to_vec(),
            times,
            gaussians_kept: last.counts.iter().map(|c| c.kept() as f64).sum::<f64>() / views,
            gaussian_candidates: last.counts.iter().map(|c| c.candidates as f64).sum::<f64>() / views,
            sky_gaussians: last.sky_gaussians,
            skipped: last.skipped,
            renders: last.renders.into_iter().map(|r| r.into_iter().map(|v| v.clamp(0.0, 1.0)).collect()).collect(),
            references: setup.references,
        })
    }

    /// The inputs of one configuration: images, input and target slots, the export's cameras (relative to the
    /// first input view), and how the scene is built.
    fn prepare(&mut self, knobs: &Knobs, inputs: &[usize], targets: &[TargetImages]) -> Result<RowSetup, BenchError> {
        let cameras = self.scene.cameras.len();
        let mut input_views = Vec::new();
        for &frame in inputs {
            for camera in 0..cameras {
                input_views.push(self.cache.get(knobs.width, frame, camera)?.clone());
            }
        }
        let mut target_views = Vec::new();
        for target in targets {
            target_views.push(self.cache.get(knobs.width, target.frame, target.camera)?.clone());
        }
        let size = input_views[0].image.size;
        let (h, w) = (size.height as usize, size.width as usize);
        let planar: Vec<f32> = input_views.iter().flat_map(|v| v.image.data.iter().copied()).collect();
        // f32 images: the network casts its input to its own float type.
        let images = Tensor::<5>::from_data(TensorData::new(planar, [1, input_views.len(), 3, h, w]), self.device);

        let frame_index = |position: usize| self.scene.frames[position].index;
        let timeline = Timeline::new(&inputs.iter().map(|&f| frame_index(f)).collect::<Vec<_>>())?;
        let reference_pose = input_views[0].world_from_camera;
        let truth = |view: &PreparedView| {
            let slot = ViewSlot { rig_camera: view.camera, time: timeline.time(frame_index(view.frame) as f64) };
            let camera = PosedCamera {
                world_from_camera: view.world_from_camera.relative_to(&reference_pose),
                intrinsics: view.intrinsics,
            };
            (slot, camera)
        };
        let (input_slots, input_cameras): (Vec<ViewSlot>, _) = input_views.iter().map(truth).unzip();
        let target_truth: Vec<(ViewSlot, PosedCamera)> = target_views.iter().map(truth).collect();
        let references = match self.options.refine.as_ref().map(|spec| spec.reference) {
            Some(ReferenceView::NearestInput) => target_truth
                .iter()
                .map(|(slot, _)| {
                    let candidates = input_slots.iter().map(|s| (s.rig_camera, s.time));
                    let position = nearest_in_time(candidates, slot.rig_camera, slot.time)
                        .ok_or_else(|| BenchError::NoReferenceView { camera: slot.rig_camera })?;
                    Ok(input_views[position].image.interleaved())
                })
                .collect::<Result<Vec<_>, BenchError>>()?,
            Some(ReferenceView::None) | None => Vec::new(),
        };
        let assembly = match knobs.culling {
            Culling::Off => AssemblySettings::exact(),
            Culling::MinOpacity(min_opacity) => AssemblySettings { min_opacity, ..AssemblySettings::default() },
        };
        let assembly =
            AssemblySettings { hidden_sky: knobs.skips.hidden_sky(), dynamic_motion: knobs.motion, ..assembly };
        let scene_options = SceneOptions { sky: knobs.sky, assembly, ..SceneOptions::default() };
        let motion = knobs.skips.motion();
        Ok(RowSetup {
            images,
            size,
            timeline,
            input_slots,
            input_cameras,
            target_truth,
            scene_options,
            motion,
            references,
        })
    }

    /// One timed run of the whole reconstruction: `[backbone, heads, assembly, raster]` milliseconds, and what it
    /// rendered.
    fn repetition(&self, model: &Dggt, setup: &RowSetup) -> Result<([f64; 4], RepetitionOutputs), BenchError> {
        let mut clock = Instant::now();
        let lap = |clock: &mut Instant| -> f64 {
            let ms = clock.elapsed().as_secs_f64() * 1e3;
            *clock = Instant::now();
            ms
        };
        let images = &setup.images;
        let aggregator = stages::backbone(model, images.clone())?;
        let prediction = stages::heads(model, aggregator, images.clone(), self.options.chunk_frames, setup.motion)?;
        settle(&prediction.pose_encoding())?;
        settle(&prediction.depth)?;
        if let Some(dynamic) = &prediction.dynamic_logit {
            settle(dynamic)?;
        }
        if let Some(maps) = &prediction.gaussians {
            settle(&maps.opacity)?;
            settle(&maps.rgb)?;
        }
        let forward_ms = lap(&mut clock);

        let cameras = match self.options.poses {
            CameraSource::GroundTruth => InputCameras::Given(setup.input_cameras.clone()),
            CameraSource::Predicted => InputCameras::Predicted,
        };
        let views = input_views(&prediction, &setup.input_slots, cameras, setup.size)?;
        let scene = prediction
            .scene(model, images, views, &setup.timeline, &setup.scene_options)?
            .ok_or_else(|| BenchError::Missing("network: no Gaussian head: nothing to render"))?;
        let mut targets = Vec::new();
        for &(slot, camera) in &setup.target_truth {
            let camera = match self.options.poses {
                CameraSource::GroundTruth => camera,
                CameraSource::Predicted => scene.camera_at(slot.rig_camera, slot.time)?,
            };
            targets.push(TargetView { rig_camera: slot.rig_camera, time: slot.time, camera });
        }
        let assembled = targets.iter().map(|target| scene.assemble(target)).collect::<Result<Vec<_>, _>>()?;
        for gaussians in &assembled {
            settle(&gaussians.gaussians.means)?;
            settle(&gaussians.gaussians.colors)?;
        }
        let assembly_ms = lap(&mut clock);

        let mut renders = Vec::new();
        let mut skipped = SkipCounts { motion_frames: prediction.motion_skipped_frames, sky_views: 0 };
        for (gaussians, target) in assembled.iter().zip(&targets) {
            let rendered = stages::rasterise(&scene, gaussians, target)?;
            skipped.sky_views += usize::from(scene.sky.is_some() && !rendered.sky_rendered);
            renders.push(rendered.rgb);
        }
        let raster_ms = lap(&mut clock);

        // The backbone alone, settled, for its time; the heads' time is the forward pass's less it. (Reading
        // the aggregator's outputs back before the heads run made the heads' outputs NaN on wgpu with burn
        // 0.22.1, so the forward pass above runs without a wait between the two.)
        let aggregator = stages::backbone(model, images.clone())?;
        if let (Some(frame_global), Some(dino)) = (aggregator.output_list.last(), aggregator.dino_token_list.last()) {
            settle(frame_global)?;
            settle(dino)?;
        }
        drop(aggregator);
        let backbone_ms = lap(&mut clock);
        let heads_ms = (forward_ms - backbone_ms).max(0.0);
        let outputs = RepetitionOutputs {
            counts: assembled.iter().map(|a| a.counts).collect(),
            sky_gaussians: scene.sky.as_ref().map_or(0, |s| s.means.dims()[0]),
            skipped,
            renders,
        };
        Ok(([backbone_ms, heads_ms, assembly_ms, raster_ms], outputs))
    }
}

/// The fixed inputs of one configuration's repetitions.
struct RowSetup {
    /// `[1, S, 3, H, W]` f32.
    images: Tensor<5>,
    size: ImageSize,
    timeline: Timeline,
    input_slots: Vec<ViewSlot>,
    /// The export's cameras of the inputs, relative to the first input view.
    input_cameras: Vec<PosedCamera>,
    /// The targets' slots and export cameras.
    target_truth: Vec<(ViewSlot, PosedCamera)>,
    scene_options: SceneOptions,
    motion: MotionPath,
    /// Per target, the refiner's reference view `[H, W, 3]`: the input view of its camera nearest in time,
    /// when the refiner takes one; empty otherwise.
    references: Vec<Vec<f32>>,
}

/// What one repetition rendered.
struct RepetitionOutputs {
    counts: Vec<AssemblyCounts>,
    sky_gaussians: usize,
    skipped: SkipCounts,
    /// Per target view, `[H, W, 3]` (not clamped).
    renders: Vec<Vec<f32>>,
}

/// Refines every render of `run` (`[H, W, 3]` at `run.size`, each attending to its reference view when the
/// run has them) `repeat` times: the median milliseconds of a pass, and the refined images.
fn refine_renders(
    refiner: &Refiner,
    latent: Latent,
    run: &RowRun,
    repeat: usize,
    device: &Device,
) -> Result<(f64, Vec<Vec<f32>>), BenchError> {
    let refine_error = |source| BenchError::Refine { doing: "refining a render", source: Box::new(source) };
    let (h, w) = (run.size.height as usize, run.size.width as usize);
    let mut times = Vec::new();
    let mut refined = Vec::new();
    for _ in 0..repeat.max(1) {
        let started = Instant::now();
        refined = run
            .renders
            .iter()
            .enumerate()
            .map(|(i, rgb)| {
                let frame = frame_from_interleaved(rgb, h, w, device)?;
                let reference = run.references.get(i).map(|r| frame_from_interleaved(r, h, w, device)).transpose()?;
                frame_to_interleaved(&refiner.refine_frames(frame, reference, latent, 1, |_| ())?, 0)
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(refine_error)?;
        times.push(started.elapsed().as_secs_f64() * 1e3);
    }
    Ok((median(times), refined))
}

/// The median (the mean of the middle two for an even count); NaN for none.
pub fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 { values[n / 2] } else { (values[n / 2 - 1] + values[n / 2]) / 2.0 }
}

/// `[H, W, 3]` `from` resized to `to` (full frame to full frame, triangle filter); a copy when equal.
pub fn resize_rgb(image: &[f32], from: ImageSize, to: ImageSize) -> Vec<f32> {
    if from == to {
        return image.to_vec();
    }
    let buffer = image::Rgb32FImage::from_raw(from.width, from.height, image.to_vec())
        .expect("a render holds width x height x 3 values");
    let resized = image::imageops::resize(&buffer, to.width, to.height, image::imageops::FilterType::Triangle);
    resized.into_raw().into_iter().map(|v| v.clamp(0.0, 1.0)).collect()
}

/// Mean PSNR, SSIM (and LPIPS) of `images` against `references`, all `[H, W, 3]` at `size`.
fn compare(
    images: &[Vec<f32>],
    references: &[Vec<f32>],
    size: ImageSize,
    lpips: Option<&Lpips>,
    device: &Device,
) -> Result<ErrorMetrics, BenchError> {
    let shape = ImageShape::new(size.height as usize, size.width as usize, 3);
    let (mut psnr, mut ssim) = (0.0, 0.0);
    for (image, reference) in images.iter().zip(references) {
        psnr += dggt_metrics::psnr(image, reference)?;
        ssim += dggt_metrics::ssim(image, reference, shape)?.value;
    }
    let n = images.len().max(1) as f64;
    let lpips = match lpips {
        Some(net) => {
            let batch = |list: &[Vec<f32>]| {
                let data: Vec<f32> = list.iter().flatten().copied().collect();
                Tensor::<4>::from_data(TensorData::new(data, [list.len(), shape.height, shape.width, 3]), device)
            };
            let values = net.eval(batch(images), batch(references))?;
            let values = host_f32(values, "LPIPS values")?;
            Some(values.iter().map(|&v| v as f64).sum::<f64>() / values.len().max(1) as f64)
        }
        None => None,
    };
    Ok(ErrorMetrics { psnr_db: psnr / n, ssim: ssim / n, lpips })
}
