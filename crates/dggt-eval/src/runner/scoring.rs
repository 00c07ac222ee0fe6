//! One rendered view scored against the export into its [`ViewRecord`]: PSNR, SSIM and LPIPS of the render,
//! the refined render and the nearest input copied; the PSNR over the dynamic mask of every image source (with
//! the crops, when asked); D-RMSE and the motion of every source at the lidar cells.

use std::path::Path;

use burn::tensor::{Tensor, TensorData};
use dggt_data::{BinaryMask, Scene, prepare_view};
use dggt_geom::ImageSize;
use dggt_geom::glam::DMat3;
use dggt_metrics::{ImageShape, MetricError, masked_psnr, psnr, ssim};
use dggt_scene::DynamicMotion;

use super::cells::{CellFlow, FlowSeen, RenderedDepth, collect_cells, read_sky_mask, score_depth, score_flow};
use super::forward::ForwardScene;
use super::setup::SceneContext;
use super::views::{RenderedFlow, host};
use crate::error::EvalError;
use crate::motion::log_from_reconstruction;
use crate::protocol::TargetKind;
use crate::report::{ImageScores, SourceFlowMetrics, SourcePsnr, ViewRecord};
use crate::sources::{ImageSource, crop_box, write_crop_strip};

/// How the nearest input copied is named among the image sources.
pub const NEAREST_INPUT: &str = "nearest input copied";

/// Which view a render is scored as.
pub(super) struct ScoredView<'a> {
    pub(super) frame: usize,
    pub(super) frame_position: usize,
    pub(super) camera_position: usize,
    pub(super) split: TargetKind,
    pub(super) time: f64,
    /// At a view between the inputs, the rendered expected flow of every moving source.
    pub(super) rendered_flows: Vec<(DynamicMotion, RenderedFlow)>,
    /// At a view between the inputs with a dynamic mask, the view rendered under every image source
    /// (interleaved, clamped).
    pub(super) source_renders: Vec<(ImageSource, Vec<f32>)>,
    /// At a view that is no input, the input view of the same camera nearest in time (interleaved).
    pub(super) nearest_input: Option<Vec<f32>>,
    /// The scene's folder of crops, when they are written.
    pub(super) crops: Option<&'a Path>,
}

/// A view's render (interleaved `[H, W, 3]`, clamped) and, with a refiner, the refined render.
#[derive(Clone, Copy)]
pub(super) struct RenderedImages<'a> {
    pub(super) rgb: &'a [f32],
    pub(super) refined: Option<&'a [f32]>,
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

/// Scores one rendered view (its images `[H, W, 3]` clamped, its depths) against the export: PSNR, SSIM,
/// LPIPS of the render (and of the refined render), and at the lidar cells D-RMSE and scene flow.
pub(super) fn score_view(
    scene: &Scene,
    forward: &ForwardScene,
    context: &SceneContext<'_>,
    view: &ScoredView<'_>,
    images: RenderedImages<'_>,
    depth: &RenderedDepth,
    seen: &mut FlowSeen,
) -> Result<ViewRecord, EvalError> {
    let prepared = prepare_view(scene, view.frame_position, view.camera_position, &context.preprocess)?;
    let truth = prepared.image.interleaved();
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
        depth_parts: None,
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

/// The predicted flow of `source` that `view` is scored with.
fn predicted_flow<'a>(
    scene: &Scene,
    forward: &'a ForwardScene,
    source: DynamicMotion,
    view: &'a ScoredView,
) -> CellFlow<'a> {
    let input_position = forward.inputs.frames.iter().position(|&f| f == view.frame);
    let truth = scene.view(view.frame_position, view.camera_position).world_from_camera.rotation_matrix();
    let log_from_world =
        |predicted: DMat3| log_from_reconstruction(scene.world_from_log.rotation_matrix(), truth, predicted);
    let rendered = view.rendered_flows.iter().find(|(s, _)| *s == source).map(|(_, rendered)| rendered);
    match (source, forward.flow(source), input_position, rendered) {
        (DynamicMotion::Held, _, _, _) => CellFlow::Held,
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
