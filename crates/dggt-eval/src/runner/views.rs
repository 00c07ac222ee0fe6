//! The target views of a scene's window and what is rendered at them: each view's camera (an input's own,
//! interpolated between the inputs, or the export's), the input view nearest it in time, and at a view between
//! the inputs the expected flow of every moving source, rasterised.

use burn::tensor::Tensor;
use dggt_data::Scene;
use dggt_geom::glam::DMat3;
use dggt_infer::CameraSource;
use dggt_model::host::host_f32;
use dggt_scene::{AssemblySettings, DynamicMotion, TargetView, nearest_in_time, render_flow};

use super::forward::{ForwardScene, export_camera};
use super::setup::SceneContext;
use crate::error::EvalError;

/// The expected flow rasterised at one target view ([`dggt_scene::render_flow`]).
pub(super) struct RenderedFlow {
    /// x, y and z planes (`H x W`, row-major) in world axes per unit of scene time.
    pub(super) planes: [Vec<f32>; 3],
    /// The target's camera rotation (world from camera), for the axes.
    pub(super) world_from_camera: DMat3,
}

/// The values of `tensor` on the host (`what` names it in an error).
pub(super) fn host<const D: usize>(tensor: Tensor<D>, what: &str) -> Result<Vec<f32>, EvalError> {
    Ok(host_f32(tensor, what)?)
}

/// The view of the protocol's camera `camera_position` at log frame `frame`: an input view from its own
/// camera, any other from the camera interpolated between the rig camera's inputs, or with the export's poses
/// its export camera.
pub(super) fn target_view(
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

/// The position among the inputs of the input view of `target`'s camera nearest it in time.
pub(super) fn nearest_input(forward: &ForwardScene, target: &TargetView) -> Option<usize> {
    let views = forward.inputs.views.iter().map(|v| (v.camera, forward.timeline.time(v.frame as f64)));
    nearest_in_time(views, target.rig_camera, target.time)
}

/// At a view between the inputs, the expected flow of every moving source, rasterised (their motion is known
/// there only through a render: the source the reconstruction renders with as it renders, the others with the
/// same assembly moving the dynamic Gaussians their way); empty at an input view or without a time base.
pub(super) fn rendered_flows(
    forward: &ForwardScene,
    target: &TargetView,
) -> Result<Vec<(DynamicMotion, RenderedFlow)>, EvalError> {
    if forward.at_input(target) {
        return Ok(Vec::new());
    }
    let mut rendered = Vec::new();
    for &(source, ref flow) in &forward.flows {
        let dynamic_motion = match (source, flow) {
            (DynamicMotion::Held, _) | (_, None) => continue,
            (moving, Some(_)) => moving,
        };
        let assembly = AssemblySettings { dynamic_motion, ..forward.scene.assembly };
        let flow = host(render_flow(&forward.scene.pixels, target, &assembly)?, "rendered flow")?;
        let planes = std::array::from_fn(|axis| flow.iter().skip(axis).step_by(3).copied().collect());
        let world_from_camera = target.camera.world_from_camera.rotation_matrix();
        rendered.push((source, RenderedFlow { planes, world_from_camera }));
    }
    Ok(rendered)
}
