//! One scene's forward pass, as in `dggt reconstruct`: the protocol's input views of the window loaded and
//! preprocessed, the network run over them, the scene assembled from its prediction, and the expected flow of
//! the input pixels under every motion source scored.

use std::path::Path;
use std::time::Instant;

use burn::tensor::{Tensor, TensorData};
use dggt_data::{PlanarImage, PreprocessPlan, Scene};
use dggt_geom::{ImageSize, PosedCamera};
use dggt_infer::{
    CameraSource, GroundTruth, InputCameras, InputSet, MotionPath, SceneOptions, ViewSlot, forward_chunked, input_views,
};
use dggt_scene::{DynamicMotion, Scene4d, TargetView, Timeline};

use super::setup::SceneContext;
use super::stages::{ASSEMBLY, FORWARD, LOAD, Stopwatch};
use crate::error::EvalError;
use crate::grid::CellMapping;
use crate::motion::InputFlow;
use crate::protocol::Protocol;

/// One scene's forward pass: its inputs, their network size and the scene to render.
pub(super) struct ForwardScene {
    pub(super) inputs: InputSet,
    /// The inputs as the network saw them, in `inputs.views`' order.
    pub(super) input_images: Vec<PlanarImage>,
    pub(super) size: ImageSize,
    /// How the export's images became the network's.
    pub(super) plan: PreprocessPlan,
    pub(super) mapping: CellMapping,
    pub(super) timeline: Timeline,
    pub(super) scene: Scene4d,
    /// Every motion source scored, [`DynamicMotion::Held`] first, with the input pixels' expected flow under it
    /// (`None` for held, or without a time base).
    pub(super) flows: Vec<(DynamicMotion, Option<InputFlow>)>,
}

impl ForwardScene {
    /// Whether `target` is one of the input views (its camera at an input's time).
    pub(super) fn at_input(&self, target: &TargetView) -> bool {
        self.scene.views().iter().any(|v| v.rig_camera == target.rig_camera && v.time == target.time)
    }

    /// The expected flow under `source`, when it was computed.
    pub(super) fn flow(&self, source: DynamicMotion) -> Option<&InputFlow> {
        self.flows.iter().find(|(s, _)| *s == source).and_then(|(_, flow)| flow.as_ref())
    }
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

/// Loads the protocol's input views of `root`, runs the network and builds the scene (timed as load, forward
/// and assembly).
pub(super) fn forward_scene(
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
    let mapping = CellMapping::new(&plan, context.options.cell_sampling);
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
pub(super) fn motion_flows(
    forward: &mut ForwardScene,
    context: &SceneContext<'_>,
    seconds_per_frame: Option<f64>,
) -> Result<Vec<(DynamicMotion, Option<InputFlow>)>, EvalError> {
    let pixels = &forward.scene.pixels;
    let mut sources = vec![DynamicMotion::Held];
    if pixels.host_velocity().is_some() {
        sources.push(DynamicMotion::Velocity);
    }
    if pixels.dynamic_logit.is_some() {
        if pixels.instances().is_none() {
            forward.scene.pixels = pixels.clone().with_instances(&context.network.assembly.instances)?;
        }
        sources.push(DynamicMotion::Instances);
    }
    if forward.scene.pixels.learnt().is_some() {
        sources.push(DynamicMotion::Learnt);
    }
    let frames_per_time = forward.timeline.frames_per_time();
    sources
        .into_iter()
        .map(|source| Ok((source, InputFlow::of(&forward.scene.pixels, source, frames_per_time, seconds_per_frame)?)))
        .collect()
}

/// The export's camera of the window's view (log frame `frame`, camera `camera_position`), as a prediction's
/// world holds it: relative to the first input view (of camera position 0), intrinsics at the network's
/// resolution.
pub(super) fn export_camera(
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
