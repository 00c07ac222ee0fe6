//! One scene evaluated: its forward pass, then every target view of the protocol rendered (with the refined
//! render, the flows, the nearest input and the image sources beside it) and scored, then the scene's notes,
//! its motion gate and its means per split.

use std::path::Path;
use std::time::Instant;

use dggt_data::{DepthSource, Scene};
use dggt_scene::{DepthStatistic, DynamicMotion};

use super::cells::{FlowSeen, RenderedDepth};
use super::forward::{forward_scene, motion_flows};
use super::outputs::{crops_folder, scene_name};
use super::refinement::{reference_view, refine_render};
use super::scoring::{RenderedImages, ScoredView, score_view};
use super::setup::SceneContext;
use super::stages::{METRICS, RENDER, Stopwatch};
use super::views::{host, nearest_input, rendered_flows, target_view};
use crate::error::EvalError;
use crate::report::{SceneReport, summarise_views};
use crate::sources::{ImageSource, clamped_colours, render_sources};

/// Motion is scored only in windows where some true flow is longer than this (STORM's rule; m/s for
/// velocity-valued exports).
pub const MOTION_GATE: f64 = 1.0;

/// Evaluates the scene export at `root` (its window `scene`) with `context`: its report, with its stage times.
pub(super) fn evaluate_scene(root: &Path, scene: &Scene, context: &SceneContext<'_>) -> Result<SceneReport, EvalError> {
    let protocol = &context.options.protocol;
    let mut watch = Stopwatch::default();
    let mut forward = forward_scene(root, scene, context, &mut watch)?;
    forward.flows = motion_flows(&mut forward, context, scene.seconds_per_frame())?;
    let mut records = Vec::new();
    let mut seen = FlowSeen::default();
    let image_sources = ImageSource::available(&forward.scene.pixels);
    let crops = crops_folder(context.options, root);
    for (frame, split) in protocol.targets() {
        let frame_position = scene
            .frames
            .iter()
            .position(|f| f.index == frame)
            .ok_or_else(|| EvalError::scene(root, format!("frame {frame} is missing")))?;
        for camera_position in 0..protocol.cameras.len() {
            let started = Instant::now();
            let target = target_view(&forward, scene, context, frame, camera_position)?;
            let assembled = forward.scene.assemble(&target)?;
            let render = forward.scene.render_assembled(&assembled, &target)?;
            let rgb = clamped_colours(render.rgb)?;
            let median = forward.scene.render_depth(&assembled, &target, DepthStatistic::Median)?;
            let depth = RenderedDepth::new(
                host(render.depth, "rendered depth")?,
                host(median, "rendered median depth")?,
                forward.size,
            );
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
                false => nearest_input(&forward, &target).map(|position| forward.input_images[position].interleaved()),
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
    } else if context.motion != DynamicMotion::Held && forward.flow(context.motion).is_none() {
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
