//! The evaluation run: scene exports + checkpoint + protocol + device -> per-view records, per-scene and
//! overall means, stage times, written as `eval.json` and `eval.md`.
//!
//! Per scene: the protocol's input frames (all chosen cameras) go through one forward pass exactly as in
//! `dggt reconstruct` (same preprocessing, chunked heads, predicted cameras; the world is the first input
//! view's camera frame). Every target view is rendered at the release's scene time of its frame: an input
//! view from its own predicted camera, any other from the camera interpolated between the predicted poses of
//! the same rig camera's inputs (`dggt_scene::interpolate_camera`; extrapolated beyond the last input): the
//! paper's unposed protocol. With [`CameraSource::GroundTruth`] the export's poses (relative to the first input
//! view) place the inputs' Gaussians and view every target instead, as a model trained with
//! `render.cameras = "ground_truth"` was trained. Beside every view that is no input, the input view of the
//! same camera nearest in time is scored as it is (the baseline a method must beat to have learnt anything). The
//! render is scored against the export's image preprocessed as the network's inputs are (network
//! resolution), its expected depth against the export's lidar depth ([`crate::grid`],
//! `dggt-metrics`), and the predicted motion against the export's scene flow.
//!
//! Motion: without predicted velocities, dynamic Gaussians are held where they were predicted and the
//! predicted motion of every surface point is zero ([`MotionSource::Held`]); its metrics are computed anyway
//! and labelled. With predicted velocities (a motion head, or the Gaussian head's velocity channels) the
//! renders use them, and the expected flow of the surface seen at each lidar cell of an input view is scored
//! in the export's axes and units ([`MotionSource::Velocity`], [`crate::motion`]). With
//! `render.dynamic_motion = "instances"` the renders move each object found among the dynamic pixels along its
//! trajectory, and that motion is scored ([`MotionSource::Instances`]). Every source the reconstruction has
//! (held; velocities when predicted; instances whenever there is a dynamic head) is also scored at the same
//! cells side by side; at a view between the inputs each source's expected flow is rasterised from the
//! Gaussians assembled its way ([`dggt_scene::render_flow`]). As STORM does, motion is
//! scored at the lidar cells (positive depth; here also not sky and inside the view) and only for windows
//! where some true flow exceeds [`MOTION_GATE`] (STORM skips samples without such motion, whose accuracies
//! would be trivially high).

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::{
    BinaryMask, DepthFlowMap, DepthSource, PlanarImage, Preprocess, PreprocessPlan, Scene, images, open_scene,
    prepare_view,
};
use dggt_geom::glam::DMat3;
use dggt_geom::{ImageSize, PosedCamera};
use dggt_infer::{
    Architecture, CameraSource, GroundTruth, InputCameras, InputSet, LoadedNetwork, MotionPath, SceneOptions, ViewSlot,
    forward_chunked, input_views, load_network,
};
use dggt_losses::{Lpips, LpipsKind};
use dggt_model::host::host_f32;
use dggt_refine::{ReferenceView, Refiner, RefinerSpec, frame_from_interleaved, frame_to_interleaved};
use dggt_scene::{AssemblySettings, DynamicMotion, Scene4d, TargetView, Timeline, nearest_in_time, render_flow};

use crate::error::EvalError;
use crate::grid::{CellMapping, cell_has_sky};
use crate::motion::{InputFlow, MotionSource, log_from_reconstruction, metres_per_unit};
use crate::protocol::Protocol;
use crate::report::{
    EvalReport, ImageScores, SceneReport, SourceFlowMetrics, SourcePsnr, StageTime, ViewRecord, summarise_scenes,
    summarise_views,
};
use crate::sources::{CropImages, ImageSource, clamped_colours, crop_box, render_sources, write_crop_strip};
use dggt_metrics::{
    FlowMetrics, ImageShape, MetricError, aligned_depth_rmse, masked_psnr, psnr, scene_flow_metrics, ssim,
};

/// Motion is scored only in windows where some true flow is longer than this (STORM's rule; m/s for
/// velocity-valued exports).
pub const MOTION_GATE: f64 = 1.0;

/// The stages timed, in order.
const STAGES: [&str; 5] = ["load", "forward", "assembly", "render", "metrics"];

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
        }
    }
}

/// Seconds per stage.
#[derive(Debug, Clone, Default)]
struct Stopwatch {
    seconds: [f64; STAGES.len()],
}

impl Stopwatch {
    fn add(&mut self, stage: usize, since: Instant) {
        self.seconds[stage] += since.elapsed().as_secs_f64();
    }

    fn list(&self) -> Vec<StageTime> {
        STAGES
            .iter()
            .zip(self.seconds)
            .map(|(stage, seconds)| StageTime { stage: stage.to_string(), seconds })
            .collect()
    }
}

const LOAD: usize = 0;
const FORWARD: usize = 1;
const ASSEMBLY: usize = 2;
const RENDER: usize = 3;
const METRICS: usize = 4;

/// Runs the evaluation on `device`, writes `eval.json` and `eval.md` to `options.out` and returns the report.
pub fn evaluate(options: &EvalOptions, device: &Device) -> Result<EvalReport, EvalError> {
    let protocol = &options.protocol;
    protocol.validate()?;
    if options.scenes.is_empty() {
        return Err(EvalError::option("--scene", "give at least one scene export"));
    }
    // Every scene is checked before the network is loaded, so that a bad one fails fast.
    let scenes: Vec<Scene> = options.scenes.iter().map(|root| open_window(root, protocol)).collect::<Result<_, _>>()?;

    let mut total = Stopwatch::default();
    let started = Instant::now();
    let network = load_network(&options.checkpoint, options.architecture.as_ref(), device)?;
    let mut warnings = network.warnings.clone();
    let preprocess = network.input_preprocess(options.width);
    let (lpips, lpips_note) = match &options.lpips {
        Some(weights) => (Some(Lpips::load(LpipsKind::Alex, &weights.alexnet, &weights.linear, device)?), None),
        None => (None, Some("not computed: no weights given (--lpips-weights alex.pth --alexnet FILE)".to_string())),
    };
    let refiner = match &options.refine {
        Some(spec) => {
            let (refiner, _) = spec.load(device).map_err(|source| EvalError::Refine {
                doing: format!("loading refiner {}", spec.describe()),
                source,
            })?;
            Some(refiner)
        }
        None => None,
    };
    total.add(LOAD, started);
    if network.model.sky_model.is_none() {
        warnings.push("the network has no sky model: renders have a black sky".into());
    }

    let motion = match network.assembly.dynamic_motion {
        DynamicMotion::Instances => MotionSource::Instances,
        DynamicMotion::Velocity if network.config.predicts_motion() => MotionSource::Velocity,
        DynamicMotion::Learnt => MotionSource::Learnt,
        DynamicMotion::Velocity | DynamicMotion::Held => MotionSource::Held,
    };
    let mut reports = Vec::new();
    for (root, scene) in options.scenes.iter().zip(&scenes) {
        tracing::info!("evaluating {}", root.display());
        let context = SceneContext {
            options,
            network: &network,
            preprocess,
            lpips: lpips.as_ref(),
            refiner: refiner.as_ref(),
            motion,
            device,
        };
        let report = evaluate_scene(root, scene, &context).map_err(|e| e.in_scene(root))?;
        for stage in &report.stages {
            if let Some(i) = STAGES.iter().position(|s| *s == stage.stage) {
                total.seconds[i] += stage.seconds;
            }
        }
        reports.push(report);
    }
    let splits = protocol.splits();
    let report = EvalReport {
        protocol: protocol.clone(),
        input_frames: protocol.input_frames(),
        checkpoint: network.info.clone(),
        preprocess,
        device: format!("{device:?}"),
        motion_source: motion.label().into(),
        poses: options.poses,
        depth_protocol: "rendered expected depth vs lidar depth (depth_flows_4, else the lidar sweep binned on the same grid), least-squares scale and shift, at \
                         cells with lidar depth > 0, no sky pixel and the centre (4 col + 2, 4 row + 2) inside the \
                         view, the render sampled bilinearly there"
            .into(),
        motion_protocol: format!(
            "STORM's EPE3D / Acc5 (EPE < 0.05 or relative < 5 %) / Acc10 (EPE < 0.1 or relative < 10 %) / angle \
             (true flow > 0.1) on the export's stored flow at the same cells, in windows with some true flow > \
             {MOTION_GATE}"
        ),
        lpips_note,
        refiner: options.refine.as_ref().map(RefinerSpec::describe),
        overall: summarise_scenes(&reports, &splits),
        scenes: reports,
        stages: total.list(),
        warnings,
    };
    write_report(&report, &options.out)?;
    Ok(report)
}

/// Writes `eval.json` and `eval.md` to `out`.
pub fn write_report(report: &EvalReport, out: &Path) -> Result<(), EvalError> {
    std::fs::create_dir_all(out).map_err(|e| EvalError::file(out, format!("cannot create the folder: {e}")))?;
    let json = serde_json::to_string_pretty(report).map_err(|e| EvalError::file(out, e.to_string()))?;
    let path = out.join("eval.json");
    std::fs::write(&path, json).map_err(|e| EvalError::file(&path, e.to_string()))?;
    let path = out.join("eval.md");
    std::fs::write(&path, report.markdown()).map_err(|e| EvalError::file(&path, e.to_string()))?;
    Ok(())
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

/// The input views of a window: the frames in `keep`, every camera.
fn restrict_inputs(window: InputSet, keep: &[usize]) -> InputSet {
    fn pick<T>(items: Vec<T>, chosen: &[bool]) -> Vec<T> {
        items.into_iter().zip(chosen).filter(|(_, c)| **c).map(|(item, _)| item).collect()
    }
    let chosen: Vec<bool> = window.views.iter().map(|v| keep.contains(&v.frame)).collect();
    let ground_truth = window.ground_truth.map(|truth| GroundTruth {
        world_from_camera: pick(truth.world_from_camera, &chosen),
        intrinsics: pick(truth.intrinsics, &chosen),
    });
    InputSet {
        frames: window.frames.into_iter().filter(|f| keep.contains(f)).collect(),
        views: pick(window.views, &chosen),
        ground_truth,
        ..window
    }
}

fn host<const D: usize>(tensor: Tensor<D>, what: &str) -> Result<Vec<f32>, EvalError> {
    Ok(host_f32(tensor, what)?)
}

/// Planar `[3, H, W]` to interleaved `[H, W, 3]`.
fn interleaved(image: &PlanarImage) -> Vec<f32> {
    let plane = image.size.area();
    (0..plane).flat_map(|i| [image.data[i], image.data[plane + i], image.data[2 * plane + i]]).collect()
}

/// The scored cells of one view: rendered depth, lidar depth and true flow, paired, and at an input view of a
/// moving reconstruction the expected flow of its pixels ([`InputFlow::planes`]).
#[derive(Debug, Default)]
struct Cells {
    predicted_depth: Vec<f32>,
    true_depth: Vec<f32>,
    true_flow: Vec<[f32; 3]>,
    predicted_flow: Vec<[f32; 3]>,
}

/// Pairs the rendered depth (and the flow `planes`, when given) with the lidar cells of `map` that are not sky
/// and fall inside the view.
fn collect_cells(
    map: &DepthFlowMap,
    sky: Option<&[u8]>,
    original: ImageSize,
    mapping: &CellMapping,
    depth: &[f32],
    planes: Option<&[Vec<f32>; 3]>,
) -> Cells {
    let mut cells = Cells::default();
    let (grid_w, grid_h) = (map.size.width as usize, map.size.height as usize);
    let (w, h) = (original.width as usize, original.height as usize);
    for row in 0..grid_h {
        for col in 0..grid_w {
            let i = row * grid_w + col;
            if map.depth[i] <= 0.0 || sky.is_some_and(|mask| cell_has_sky(mask, w, h, row, col)) {
                continue;
            }
            if let Some(predicted) = mapping.sample(depth, row, col) {
                cells.predicted_depth.push(predicted);
                cells.true_depth.push(map.depth[i]);
                if let Some(flow) = &map.flow {
                    cells.true_flow.push(flow[i]);
                }
                if let Some(planes) = planes {
                    let axis = |a: usize| mapping.sample(&planes[a], row, col).unwrap_or(0.0);
                    cells.predicted_flow.push([axis(0), axis(1), axis(2)]);
                }
            }
        }
    }
    cells
}

/// What every scene of an evaluation is evaluated with.
struct SceneContext<'a> {
    options: &'a EvalOptions,
    network: &'a LoadedNetwork,
    preprocess: Preprocess,
    lpips: Option<&'a Lpips>,
    refiner: Option<&'a Refiner>,
    motion: MotionSource,
    device: &'a Device,
}

/// One scene's forward pass: its inputs, their network size and the scene to render.
struct ForwardScene {
    inputs: InputSet,
    /// The inputs as the network saw them, in `inputs.views`' order.
    input_images: Vec<PlanarImage>,
    size: ImageSize,
    /// How the export's images became the network's.
    plan: PreprocessPlan,
    mapping: CellMapping,
    timeline: Timeline,
    scene: Scene4d,
    /// Every motion source scored, [`MotionSource::Held`] first, with the input pixels' expected flow under it
    /// (`None` for held, or without a time base).
    flows: Vec<(MotionSource, Option<InputFlow>)>,
}

impl ForwardScene {
    /// Whether `target` is one of the input views (its camera at an input's time).
    fn at_input(&self, target: &TargetView) -> bool {
        self.scene.views().iter().any(|v| v.rig_camera == target.rig_camera && v.time == target.time)
    }

    /// The expected flow under `source`, when it was computed.
    fn flow(&self, source: MotionSource) -> Option<&InputFlow> {
        self.flows.iter().find(|(s, _)| *s == source).and_then(|(_, flow)| flow.as_ref())
    }
}

/// Whether the scene's scored cells carry depth and flow, and the longest true flow among them.
#[derive(Debug, Default)]
struct FlowSeen {
    has_depth_flow: bool,
    largest_flow: f64,
}

fn evaluate_scene(root: &Path, scene: &Scene, context: &SceneContext<'_>) -> Result<SceneReport, EvalError> {
    let protocol = &context.options.protocol;
    let mut watch = Stopwatch::default();
    let mut forward = forward_scene(root, scene, context, &mut watch)?;
    forward.flows = motion_flows(&mut forward, context, scene.seconds_per_frame())?;
    let mut records = Vec::new();
    let mut seen = FlowSeen::default();
    let image_sources = ImageSource::available(&forward.scene.pixels);
    let crops = match context.options.crops {
        CropImages::Write => Some(context.options.out.join("crops").join(scene_name(root))),
        CropImages::Skip => None,
    };
    for (frame, split) in protocol.targets() {
        let frame_position = scene
            .frames
            .iter()
            .position(|f| f.index == frame)
            .ok_or_else(|| EvalError::scene(root, format!("frame {frame} is missing")))?;
        for camera_position in 0..protocol.cameras.len() {
            let started = Instant::now();
            let target = target_view(&forward, scene, context, frame, camera_position)?;
            let render = forward.scene.render(&target)?;
            let rgb = clamped_colours(render.rgb)?;
            let depth = host(render.depth, "rendered depth")?;
            let refined = match context.refiner {
                Some(refiner) => {
                    let reference = reference_view(&forward, &target, context)?;
                    Some(refine_render(refiner, &rgb, reference, forward.size, context)?)
                }
                None => None,
            };
            let rendered_flows = rendered_flows(&forward, &target)?;
            let has_mask = scene.view(frame_position, camera_position).files.dynamic_mask.is_some();
            let nearest_input = match forward.at_input(&target) {
                true => None,
                false => nearest_input(&forward, &target).map(|position| interleaved(&forward.input_images[position])),
            };
            let source_renders = match has_mask && !forward.at_input(&target) {
                true => render_sources(&forward.scene, &target, &image_sources, &rgb)?,
                false => Vec::new(),
            };
            watch.add(RENDER, started);

            let started = Instant::now();
            let view = ScoredView {
                frame,
                frame_position,
                camera_position,
                split,
                time: target.time,
                rendered_flows,
                source_renders,
                nearest_input,
                crops: crops.as_deref(),
            };
            let images = RenderedImages { rgb: &rgb, refined: refined.as_deref() };
            records.push(score_view(scene, &forward, context, &view, images, &depth, &mut seen)?);
            watch.add(METRICS, started);
        }
    }
    let mut notes = Vec::new();
    if !seen.has_depth_flow {
        notes.push("the export has neither depth_flows_4 nor lidar: no D-RMSE or motion metrics".into());
    } else if scene.depth_source() == Some(DepthSource::Lidar) {
        notes.push("depth from the projected lidar sweeps, which carry no scene flow: no motion metrics".into());
    } else if context.motion != MotionSource::Held && forward.flow(context.motion).is_none() {
        notes.push("one input frame or no frame interval: predicted motion has no time base, motion not scored".into());
    } else if seen.largest_flow <= MOTION_GATE {
        for record in &mut records {
            record.motion = None;
            record.motion_by_source.clear();
        }
        notes.push(format!(
            "no true scene flow above {MOTION_GATE} at the scored cells (largest {:.3}): motion metrics not evaluated",
            seen.largest_flow
        ));
    }
    if forward.scene.sky.is_none() {
        notes.push("no sky model: the sky renders black".into());
    }
    let splits = protocol.splits().into_iter().map(|split| summarise_views(&records, split)).collect();
    Ok(SceneReport {
        path: root.to_path_buf(),
        name: scene_name(root),
        input_frames: protocol.input_frames(),
        network_size: [forward.size.width, forward.size.height],
        views: records,
        splits,
        stages: watch.list(),
        scene_flow: scene.flow_origin()?,
        notes,
    })
}

/// A scene's name in the reports: its folder's name.
fn scene_name(root: &Path) -> String {
    root.file_name().map_or_else(|| root.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// At a view between the inputs, the expected flow of every moving source, rasterised (their motion is known
/// there only through a render: the source the reconstruction renders with as it renders, the others with the
/// same assembly moving the dynamic Gaussians their way); empty at an input view or without a time base.
fn rendered_flows(forward: &ForwardScene, target: &TargetView) -> Result<Vec<(MotionSource, RenderedFlow)>, EvalError> {
    if forward.at_input(target) {
        return Ok(Vec::new());
    }
    let mut rendered = Vec::new();
    for &(source, ref flow) in &forward.flows {
        let dynamic_motion = match (source, flow) {
            (MotionSource::Velocity, Some(_)) => DynamicMotion::Velocity,
            (MotionSource::Instances, Some(_)) => DynamicMotion::Instances,
            (MotionSource::Learnt, Some(_)) => DynamicMotion::Learnt,
            _ => continue,
        };
        let assembly = AssemblySettings { dynamic_motion, ..forward.scene.assembly };
        let flow = host(render_flow(&forward.scene.pixels, target, &assembly)?, "rendered flow")?;
        let planes = std::array::from_fn(|axis| flow.iter().skip(axis).step_by(3).copied().collect());
        let world_from_camera = target.camera.world_from_camera.rotation_matrix();
        rendered.push((source, RenderedFlow { planes, world_from_camera }));
    }
    Ok(rendered)
}

/// Loads the protocol's input views of `root`, runs the network and builds the scene (timed as load, forward
/// and assembly).
fn forward_scene(
    root: &Path,
    scene: &Scene,
    context: &SceneContext<'_>,
    watch: &mut Stopwatch,
) -> Result<ForwardScene, EvalError> {
    let (protocol, network) = (&context.options.protocol, context.network);
    let started = Instant::now();
    let window = InputSet::open(root, Some(protocol.window()), Some(protocol.cameras.clone()))?;
    let inputs = restrict_inputs(window, &protocol.input_frames());
    let (input_images, size) = inputs.load(&context.preprocess)?;
    let plan = context.preprocess.plan(inputs.size)?;
    let mapping = CellMapping::new(&plan);
    let data: Vec<f32> = input_images.iter().flat_map(|i| i.data.iter().copied()).collect();
    let (h, w) = (size.height as usize, size.width as usize);
    let batch = Tensor::<5>::from_data(TensorData::new(data, [1, input_images.len(), 3, h, w]), context.device);
    watch.add(LOAD, started);

    let started = Instant::now();
    let prediction =
        forward_chunked(&network.model, batch.clone(), context.options.chunk_frames, MotionPath::WhereDynamic)?;
    let timeline = Timeline::new(&inputs.frames)?;
    let slots: Vec<ViewSlot> =
        inputs.views.iter().map(|v| ViewSlot { rig_camera: v.camera, time: timeline.time(v.frame as f64) }).collect();
    let cameras = match context.options.poses {
        CameraSource::Predicted => InputCameras::Predicted,
        CameraSource::GroundTruth => InputCameras::Given(
            inputs
                .views
                .iter()
                .map(|v| export_camera(scene, &plan, protocol, v.frame, v.camera))
                .collect::<Result<_, _>>()?,
        ),
    };
    let views = input_views(&prediction, &slots, cameras, size)?;
    watch.add(FORWARD, started);

    let started = Instant::now();
    let scene_options = SceneOptions { assembly: network.assembly, ..SceneOptions::default() };
    let mut scene = prediction
        .scene(&network.model, &batch, views, &timeline, &scene_options)?
        .ok_or_else(|| EvalError::NoGaussianHead { checkpoint: context.options.checkpoint.clone() })?;
    // The learnt flow is scored side by side even when the renders do not move along it.
    if let (Some(head), Some(features), None) =
        (&network.model.flow_head, &prediction.flow_features, scene.pixels.learnt())
    {
        scene.pixels = scene.pixels.with_learnt_flow(head, features)?;
    }
    drop(prediction);
    watch.add(ASSEMBLY, started);
    Ok(ForwardScene { inputs, input_images, size, plan, mapping, timeline, scene, flows: Vec::new() })
}

/// The motion sources scored side by side (held; the predicted velocities when the network has them; the
/// instances when it has a dynamic head, found here for scoring when the reconstruction does not render with
/// them) and the input pixels' expected flow under each.
fn motion_flows(
    forward: &mut ForwardScene,
    context: &SceneContext<'_>,
    seconds_per_frame: Option<f64>,
) -> Result<Vec<(MotionSource, Option<InputFlow>)>, EvalError> {
    let pixels = &forward.scene.pixels;
    let mut sources = vec![MotionSource::Held];
    if pixels.host_velocity().is_some() {
        sources.push(MotionSource::Velocity);
    }
    if pixels.dynamic_logit.is_some() {
        if pixels.instances().is_none() {
            forward.scene.pixels = pixels.clone().with_instances(&context.network.assembly.instances)?;
        }
        sources.push(MotionSource::Instances);
    }
    if forward.scene.pixels.learnt().is_some() {
        sources.push(MotionSource::Learnt);
    }
    let frames_per_time = forward.timeline.frames_per_time();
    sources
        .into_iter()
        .map(|source| Ok((source, InputFlow::of(&forward.scene.pixels, source, frames_per_time, seconds_per_frame)?)))
        .collect()
}

/// The view of the protocol's camera `camera_position` at log frame `frame`: an input view from its own
/// camera, any other from the camera interpolated between the rig camera's inputs, or with the export's poses
/// its export camera.
fn target_view(
    forward: &ForwardScene,
    scene: &Scene,
    context: &SceneContext<'_>,
    frame: usize,
    camera_position: usize,
) -> Result<TargetView, EvalError> {
    let (time, protocol) = (forward.timeline.time(frame as f64), &context.options.protocol);
    let cameras = forward.inputs.cameras.len();
    let camera = match (forward.inputs.frames.iter().position(|&f| f == frame), context.options.poses) {
        (Some(input_position), _) => forward.scene.views()[input_position * cameras + camera_position].camera,
        (None, CameraSource::Predicted) => forward.scene.camera_at(camera_position, time)?,
        (None, CameraSource::GroundTruth) => export_camera(scene, &forward.plan, protocol, frame, camera_position)?,
    };
    Ok(TargetView { rig_camera: camera_position, time, camera })
}

/// The export's camera of the window's view (log frame `frame`, camera `camera_position`), as a prediction's
/// world holds it: relative to the first input view (of camera position 0), intrinsics at the network's
/// resolution.
fn export_camera(
    scene: &Scene,
    plan: &PreprocessPlan,
    protocol: &Protocol,
    frame: usize,
    camera_position: usize,
) -> Result<PosedCamera, EvalError> {
    let position = |frame: usize| {
        let missing = || EvalError::option("--frames", format!("frame {frame} is not in the scene's window"));
        scene.frames.iter().position(|f| f.index == frame).ok_or_else(missing)
    };
    let first_input = protocol.input_frames()[0];
    let reference = scene.view(position(first_input)?, 0).world_from_camera;
    Ok(PosedCamera {
        world_from_camera: scene.view(position(frame)?, camera_position).world_from_camera.relative_to(&reference),
        intrinsics: plan.intrinsics(&scene.cameras[camera_position].intrinsics),
    })
}

/// The position among the inputs of the input view of `target`'s camera nearest it in time.
fn nearest_input(forward: &ForwardScene, target: &TargetView) -> Option<usize> {
    let views = forward.inputs.views.iter().map(|v| (v.camera, forward.timeline.time(v.frame as f64)));
    nearest_in_time(views, target.rig_camera, target.time)
}

/// Which view a render is scored as.
struct ScoredView<'a> {
    frame: usize,
    frame_position: usize,
    camera_position: usize,
    split: crate::protocol::TargetKind,
    time: f64,
    /// At a view between the inputs, the rendered expected flow of every moving source.
    rendered_flows: Vec<(MotionSource, RenderedFlow)>,
    /// At a view between the inputs with a dynamic mask, the view rendered under every image source
    /// (interleaved, clamped).
    source_renders: Vec<(ImageSource, Vec<f32>)>,
    /// At a view that is no input, the input view of the same camera nearest in time (interleaved).
    nearest_input: Option<Vec<f32>>,
    /// The scene's folder of crops, when they are written.
    crops: Option<&'a Path>,
}

/// The expected flow rasterised at one target view ([`dggt_scene::render_flow`]).
struct RenderedFlow {
    /// x, y and z planes (`H x W`, row-major) in world axes per unit of scene time.
    planes: [Vec<f32>; 3],
    /// The target's camera rotation (world from camera), for the axes.
    world_from_camera: DMat3,
}

/// A view's render (interleaved `[H, W, 3]`, clamped) and, with a refiner, the refined render.
#[derive(Clone, Copy)]
struct RenderedImages<'a> {
    rgb: &'a [f32],
    refined: Option<&'a [f32]>,
}

/// PSNR, SSIM and (with weights) LPIPS of `rgb` against `truth`, both interleaved `[H, W, 3]` of `size`.
fn image_scores(
    rgb: &[f32],
    truth: &[f32],
    size: ImageSize,
    context: &SceneContext<'_>,
) -> Result<ImageScores, EvalError> {
    let (h, w) = (size.height as usize, size.width as usize);
    let lpips = match context.lpips {
        Some(lpips) => {
            let as_tensor =
                |values: Vec<f32>| Tensor::<4>::from_data(TensorData::new(values, [1, h, w, 3]), context.device);
            let value = lpips.eval(as_tensor(rgb.to_vec()), as_tensor(truth.to_vec()))?;
            Some(f64::from(host(value, "LPIPS")?[0]))
        }
        None => None,
    };
    Ok(ImageScores { psnr: psnr(rgb, truth)?, ssim: ssim(rgb, truth, ImageShape::new(h, w, 3))?.value, lpips })
}

/// The refiner's reference view for `target` (interleaved), as the spec asks: none, or the input view of the
/// target's camera nearest in time.
fn reference_view(
    forward: &ForwardScene,
    target: &TargetView,
    context: &SceneContext<'_>,
) -> Result<Option<Vec<f32>>, EvalError> {
    let spec = context.options.refine.as_ref().expect("a refiner comes from its spec");
    match spec.reference {
        ReferenceView::None => Ok(None),
        ReferenceView::NearestInput => {
            let position =
                nearest_input(forward, target).ok_or(EvalError::NoReferenceView { camera: target.rig_camera })?;
            Ok(Some(interleaved(&forward.input_images[position])))
        }
    }
}

/// The render `rgb` (interleaved, clamped) after the refiner, attending to `reference` (interleaved) when
/// given; interleaved.
fn refine_render(
    refiner: &Refiner,
    rgb: &[f32],
    reference: Option<Vec<f32>>,
    size: ImageSize,
    context: &SceneContext<'_>,
) -> Result<Vec<f32>, EvalError> {
    let refine_error = |source| EvalError::Refine { doing: "refining a render".into(), source };
    let spec = context.options.refine.as_ref().expect("a refiner comes from its spec");
    let (h, w) = (size.height as usize, size.width as usize);
    let frame = frame_from_interleaved(rgb, h, w, context.device).map_err(refine_error)?;
    let reference =
        reference.map(|rgb| frame_from_interleaved(&rgb, h, w, context.device)).transpose().map_err(refine_error)?;
    let refined = refiner.refine_frames(frame, reference, spec.latent, 1, |_| ()).map_err(refine_error)?;
    frame_to_interleaved(&refined, 0).map_err(refine_error)
}

/// Scores one rendered view (its images `[H, W, 3]` clamped, `depth` `[H, W]`) against the export: PSNR, SSIM,
/// LPIPS of the render (and of the refined render), and at the lidar cells D-RMSE and scene flow.
fn score_view(
    scene: &Scene,
    forward: &ForwardScene,
    context: &SceneContext<'_>,
    view: &ScoredView<'_>,
    images: RenderedImages<'_>,
    depth: &[f32],
    seen: &mut FlowSeen,
) -> Result<ViewRecord, EvalError> {
    let prepared = prepare_view(scene, view.frame_position, view.camera_position, &context.preprocess)?;
    let truth = interleaved(&prepared.image);
    let scores = image_scores(images.rgb, &truth, forward.size, context)?;
    let refined = images.refined.map(|rgb| image_scores(rgb, &truth, forward.size, context)).transpose()?;
    let (dynamic_psnr, dynamic_pixels) = moving_region_psnr(images.rgb, &truth, prepared.dynamic_mask.as_ref())?;
    let camera = &scene.cameras[view.camera_position];
    let mut record = ViewRecord {
        frame: view.frame,
        camera: context.options.protocol.cameras[view.camera_position],
        camera_name: camera.name.clone(),
        split: view.split,
        scene_time: view.time,
        psnr: scores.psnr,
        ssim: scores.ssim,
        lpips: scores.lpips,
        dynamic_psnr,
        dynamic_pixels,
        d_rmse: None,
        abs_rel: None,
        depth_scale: None,
        depth_shift: None,
        depth_cells: 0,
        depth_note: None,
        motion: None,
        motion_by_source: Vec::new(),
        dynamic_psnr_by_source: Vec::new(),
        refined,
        nearest_input: view
            .nearest_input
            .as_deref()
            .map(|copy| image_scores(copy, &truth, forward.size, context))
            .transpose()?,
    };
    if let Some(mask) = prepared.dynamic_mask.as_ref().filter(|_| !view.source_renders.is_empty()) {
        record.dynamic_psnr_by_source = sources_on_mask(view, &truth, mask, forward.size, &record)?;
    }
    let files = &scene.view(view.frame_position, view.camera_position).files;
    match scene.depth_map(view.frame_position, view.camera_position)? {
        None => record.depth_note = Some("the export has neither a depth_flows_4 map nor lidar for this view".into()),
        Some(map) => {
            seen.has_depth_flow = true;
            let sky_mask = read_sky_mask(files.sky_mask.as_deref(), camera.size)?;
            let mut by_source = Vec::new();
            for (position, &(source, _)) in forward.flows.iter().enumerate() {
                let predicted = predicted_flow(scene, forward, source, view);
                let planes = match predicted {
                    CellFlow::Sampled { planes, .. } => Some(planes),
                    CellFlow::Held | CellFlow::Unscored => None,
                };
                let cells = collect_cells(&map, sky_mask.as_deref(), camera.size, &forward.mapping, depth, planes);
                if position == 0 {
                    score_depth(&mut record, &cells, seen)?;
                }
                let metrics = score_flow(&cells, predicted)?;
                if source == context.motion {
                    record.motion = metrics;
                }
                by_source.push(metrics.map(|metrics| SourceFlowMetrics { source: source.name().into(), metrics }));
            }
            // Side by side only where every source is scored, so that the sources' means cover the same views.
            if by_source.len() > 1 {
                record.motion_by_source = by_source.into_iter().collect::<Option<Vec<_>>>().unwrap_or_default();
            }
        }
    }
    Ok(record)
}

/// How the nearest input copied is named among the image sources.
pub const NEAREST_INPUT: &str = "nearest input copied";

/// Every image source's PSNR over `mask` at `view`, and the nearest input copied, and with a crop folder the strip of their crops beside the
/// truth (none for an empty mask).
fn sources_on_mask(
    view: &ScoredView<'_>,
    truth: &[f32],
    mask: &BinaryMask,
    size: ImageSize,
    record: &ViewRecord,
) -> Result<Vec<SourcePsnr>, EvalError> {
    let Some(area) = crop_box(mask) else { return Ok(Vec::new()) };
    let mut scores = Vec::new();
    let copied = view.nearest_input.as_deref().map(|rgb| (NEAREST_INPUT, rgb));
    let renders = view.source_renders.iter().map(|(source, rgb)| (source.name(), &rgb[..]));
    for (source, rgb) in renders.chain(copied) {
        if let (Some(dynamic_psnr), _) = moving_region_psnr(rgb, truth, Some(mask))? {
            scores.push(SourcePsnr { source: source.into(), dynamic_psnr, count: 1 });
        }
    }
    if let Some(folder) = view.crops {
        let path = folder.join(format!("f{:04}_c{}.png", record.frame, record.camera));
        let images: Vec<&[f32]> =
            std::iter::once(truth).chain(view.source_renders.iter().map(|(_, rgb)| &rgb[..])).collect();
        write_crop_strip(&path, size, area, &images)?;
    }
    Ok(scores)
}

/// PSNR of the render over the pixels of the view's dynamic mask (interleaved RGB of the network's size), and
/// how many pixels that is; `None` without a mask or with an empty one.
fn moving_region_psnr(
    rgb: &[f32],
    truth: &[f32],
    mask: Option<&BinaryMask>,
) -> Result<(Option<f64>, usize), EvalError> {
    let Some(mask) = mask else { return Ok((None, 0)) };
    let moving: Vec<bool> = mask.data.iter().map(|&v| v > 0).collect();
    let pixels = moving.iter().filter(|&&m| m).count();
    match masked_psnr(rgb, truth, 3, &moving) {
        Ok(value) => Ok((Some(value), pixels)),
        Err(MetricError::Empty { .. }) => Ok((None, 0)),
        Err(other) => Err(other.into()),
    }
}

/// The export's sky mask of a view at its original size, if it has one.
fn read_sky_mask(path: Option<&Path>, original: ImageSize) -> Result<Option<Vec<u8>>, EvalError> {
    let Some(path) = path else { return Ok(None) };
    let mask = images::read_gray(path)?;
    images::expect_size(path, ImageSize { width: mask.width(), height: mask.height() }, original)?;
    Ok(Some(mask.into_raw()))
}

/// What the predicted flow at a view's cells is.
#[derive(Clone, Copy)]
enum CellFlow<'a> {
    /// Zero everywhere: nothing moves.
    Held,
    /// Not known at this view (no time base).
    Unscored,
    /// Sampled from `planes` (an input view's, or the rendered flow of a view between them), in `flow`'s units,
    /// and brought into the log world's axes by `log_from_world`.
    Sampled { flow: &'a InputFlow, planes: &'a [Vec<f32>; 3], log_from_world: DMat3 },
}

/// The predicted flow of `source` that `view` is scored with.
fn predicted_flow<'a>(
    scene: &Scene,
    forward: &'a ForwardScene,
    source: MotionSource,
    view: &'a ScoredView,
) -> CellFlow<'a> {
    let input_position = forward.inputs.frames.iter().position(|&f| f == view.frame);
    let truth = scene.view(view.frame_position, view.camera_position).world_from_camera.rotation_matrix();
    let log_from_world =
        |predicted: DMat3| log_from_reconstruction(scene.world_from_log.rotation_matrix(), truth, predicted);
    let rendered = view.rendered_flows.iter().find(|(s, _)| *s == source).map(|(_, rendered)| rendered);
    match (source, forward.flow(source), input_position, rendered) {
        (MotionSource::Held, _, _, _) => CellFlow::Held,
        (_, Some(flow), Some(position), _) => {
            let input_view = position * forward.inputs.cameras.len() + view.camera_position;
            let predicted = forward.scene.views()[input_view].camera.world_from_camera.rotation_matrix();
            CellFlow::Sampled { flow, planes: flow.planes(input_view), log_from_world: log_from_world(predicted) }
        }
        (_, Some(flow), None, Some(rendered)) => CellFlow::Sampled {
            flow,
            planes: &rendered.planes,
            log_from_world: log_from_world(rendered.world_from_camera),
        },
        _ => CellFlow::Unscored,
    }
}

/// D-RMSE of `cells` into `record`, and the longest true flow among them into `seen`.
fn score_depth(record: &mut ViewRecord, cells: &Cells, seen: &mut FlowSeen) -> Result<(), EvalError> {
    record.depth_cells = cells.true_depth.len();
    match aligned_depth_rmse(&cells.predicted_depth, &cells.true_depth) {
        Ok(alignment) => {
            record.d_rmse = Some(alignment.rmse);
            record.abs_rel = Some(alignment.abs_rel);
            record.depth_scale = Some(alignment.scale);
            record.depth_shift = Some(alignment.shift);
        }
        Err(MetricError::Empty { .. }) => {
            record.depth_note = Some("no lidar cell outside the sky inside the view".into())
        }
        Err(other) => return Err(other.into()),
    }
    let longest =
        cells.true_flow.iter().map(|f| f.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt()).fold(0.0, f64::max);
    seen.largest_flow = seen.largest_flow.max(longest);
    Ok(())
}

/// The scene-flow metrics of `cells` under `predicted`; a sampled flow is brought to metres by the view's depth
/// scale ([`metres_per_unit`]; not scored without one). `None` without true flow or a prediction.
fn score_flow(cells: &Cells, predicted: CellFlow<'_>) -> Result<Option<FlowMetrics>, EvalError> {
    if cells.true_flow.is_empty() {
        return Ok(None);
    }
    let predicted: Option<Vec<[f32; 3]>> = match predicted {
        CellFlow::Held => Some(vec![[0.0; 3]; cells.true_flow.len()]),
        CellFlow::Unscored => None,
        CellFlow::Sampled { flow, log_from_world, .. } => metres_per_unit(&cells.predicted_depth, &cells.true_depth)
            .map(|scale| {
                cells.predicted_flow.iter().map(|&f| flow.in_export_units(f, log_from_world, scale)).collect()
            }),
    };
    predicted.map(|predicted| scene_flow_metrics(&predicted, &cells.true_flow)).transpose().map_err(Into::into)
}
