//! One training sample as tensors: the input images for the network, and per view the ground truth the losses
//! compare with (image, masks, the export's camera, depth and scene flow where the export has them).
//!
//! Ground-truth cameras are re-expressed in the frame of the first input view (`world' = camera of input 0`),
//! the frame the camera head predicts in, so they can stand in for predicted cameras and supervise them.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::{LoadedSample, PreparedView, Preprocess, Scene};
use dggt_geom::{ImageSize, PosedCamera};
use dggt_scene::Timeline;

use crate::error::ObjectiveError;

/// One view's ground truth.
#[derive(Debug, Clone)]
pub struct ViewTruth {
    /// Position in the scene's frame list.
    pub frame: usize,
    pub rig_camera: usize,
    /// Scene time on the sample's [`Timeline`].
    pub time: f64,
    /// The export's camera, in the first input view's frame.
    pub camera: PosedCamera,
    /// `[H, W, 3]` RGB in `[0, 1]`.
    pub image: Tensor<3>,
    /// `[H, W]` 1 where sky.
    pub sky: Option<Tensor<2>>,
    /// `[H, W]` 1 where dynamic.
    pub dynamic: Option<Tensor<2>>,
    /// The export's depth and scene flow where it measured them.
    pub depth_flow: Option<DepthFlowSamples>,
}

/// The quarter-resolution depth cells of one view (the export's `depth_flows_4`, or its lidar), at the pixels
/// of the preprocessed image their centres land on (cells without a depth, such as sky, are left out).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFlowSamples {
    /// Row-major indices into the preprocessed image.
    pub pixels: Vec<i64>,
    /// z-depths in world units.
    pub depths: Vec<f32>,
    /// Scene flow in the view's camera axes (OpenCV) and world units per log frame, the motion head's units;
    /// `None` when the depth came from lidar (no flow) or the scene has a single frame and so no frame interval.
    pub velocities: Option<Vec<[f32; 3]>>,
    /// Whether each cell moves faster than [`MOVING_SPEED`] (empty without flow).
    pub moving: Vec<bool>,
}

/// Speed, in the export's units per second, above which a cell counts as moving (the dynamic masks' 1 m/s).
pub const MOVING_SPEED: f32 = 1.0;

/// A sample ready for a training step.
#[derive(Debug, Clone)]
pub struct StepBatch {
    pub step: u64,
    /// `[1, S, 3, H, W]` the network's input.
    pub images: Tensor<5>,
    pub size: ImageSize,
    pub timeline: Timeline,
    pub inputs: Vec<ViewTruth>,
    pub targets: Vec<ViewTruth>,
}

/// Which views of a batch read the export's depth-and-flow maps (`depth_flows_4`): only the depth and flow
/// losses use them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthFlowMaps {
    /// None.
    Skip,
    /// The input views (the network's depth, its velocities, the learnt flow).
    Inputs,
    /// The inputs and the targets (the rendered depth too).
    InputsAndTargets,
}

impl StepBatch {
    /// Moves a decoded sample to `device`, with the inputs' depth-and-flow maps as `maps` says.
    pub fn new(
        sample: &LoadedSample,
        scene: &Scene,
        preprocess: &Preprocess,
        maps: DepthFlowMaps,
        device: &Device,
    ) -> Result<Self, ObjectiveError> {
        let first = sample.inputs.first().ok_or(ObjectiveError::NoInputViews { step: sample.step })?;
        let size = first.image.size;
        if let Some(view) = sample.inputs.iter().chain(&sample.targets).find(|v| v.image.size != size) {
            return Err(ObjectiveError::ViewSize {
                frame: view.frame,
                camera: view.camera,
                size: view.image.size,
                first: size,
            });
        }
        let timeline = Timeline::new(&sample.sample.input_frames)?;
        let reference = first.world_from_camera;
        let truth = |view: &PreparedView, maps: DepthFlowMaps| -> Result<ViewTruth, ObjectiveError> {
            Ok(ViewTruth {
                frame: view.frame,
                rig_camera: view.camera,
                time: timeline.time(view.frame as f64),
                camera: PosedCamera {
                    world_from_camera: view.world_from_camera.relative_to(&reference),
                    intrinsics: view.intrinsics,
                },
                image: hwc_image(view, device),
                sky: view.sky_mask.as_ref().map(|m| mask_tensor(&m.data, size, device)),
                dynamic: view.dynamic_mask.as_ref().map(|m| mask_tensor(&m.data, size, device)),
                depth_flow: match maps {
                    DepthFlowMaps::Inputs | DepthFlowMaps::InputsAndTargets => {
                        depth_flow_samples(scene, preprocess, view)?
                    }
                    DepthFlowMaps::Skip => None,
                },
            })
        };
        let inputs = sample.inputs.iter().map(|v| truth(v, maps)).collect::<Result<Vec<_>, _>>()?;
        let target_maps = if maps == DepthFlowMaps::InputsAndTargets { maps } else { DepthFlowMaps::Skip };
        let targets = sample.targets.iter().map(|v| truth(v, target_maps)).collect::<Result<Vec<_>, _>>()?;
        let (h, w) = (size.height as usize, size.width as usize);
        let planar: Vec<f32> = sample.inputs.iter().flat_map(|v| v.image.data.iter().copied()).collect();
        let images = Tensor::from_data(TensorData::new(planar, [1, sample.inputs.len(), 3, h, w]), device);
        Ok(Self { step: sample.step, images, size, timeline, inputs, targets })
    }
}

fn hwc_image(view: &PreparedView, device: &Device) -> Tensor<3> {
    let (h, w) = (view.image.size.height as usize, view.image.size.width as usize);
    Tensor::<3>::from_data(TensorData::new(view.image.data.clone(), [3, h, w]), device).permute([1, 2, 0])
}

fn mask_tensor(mask: &[u8], size: ImageSize, device: &Device) -> Tensor<2> {
    let values: Vec<f32> = mask.iter().map(|&m| if m > 0 { 1.0 } else { 0.0 }).collect();
    Tensor::from_data(TensorData::new(values, [size.height as usize, size.width as usize]), device)
}

/// The view's quarter-resolution depth (and flow, where the export has it: see [`Scene::depth_map`]) mapped to
/// pixels of the preprocessed image: a cell's centre `(4 col + 2, 4 row + 2)` (continuous coordinates of the
/// original image) lands at the scaled position less the rows cropped from the top. The flow (the log world's
/// axes, world units per second) is rotated into the view's camera axes and scaled to one log frame. `None` when
/// the export has neither depth maps nor lidar for the view.
pub fn depth_flow_samples(
    scene: &Scene,
    preprocess: &Preprocess,
    view: &PreparedView,
) -> Result<Option<DepthFlowSamples>, ObjectiveError> {
    let Some(map) = scene.depth_map(view.frame, view.camera)? else { return Ok(None) };
    let original = scene.cameras[view.camera].size;
    let plan = preprocess.plan(original)?;
    let sx = plan.resized.width as f64 / original.width as f64;
    let sy = plan.resized.height as f64 / original.height as f64;
    let (w, h) = (plan.output.width as i64, plan.output.height as i64);
    let camera_from_log = view.world_from_camera.inverse().rotation_matrix() * scene.world_from_log.rotation_matrix();
    let seconds_per_frame = scene.seconds_per_frame();
    let (mut pixels, mut depths, mut velocities, mut moving) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (i, &d) in map.depth.iter().enumerate() {
        if !(d > 0.0) {
            continue;
        }
        let (row, col) = ((i / map.size.width as usize) as f64, (i % map.size.width as usize) as f64);
        let x = ((4.0 * col + 2.0) * sx).floor() as i64;
        let y = ((4.0 * row + 2.0) * sy - plan.crop_top as f64).floor() as i64;
        if !((0..w).contains(&x) && (0..h).contains(&y)) {
            continue;
        }
        pixels.push(y * w + x);
        depths.push(d);
        if let Some(flow) = &map.flow {
            let [fx, fy, fz] = flow[i].map(f64::from);
            let velocity = camera_from_log * dggt_geom::glam::DVec3::new(fx, fy, fz) * seconds_per_frame.unwrap_or(0.0);
            velocities.push(velocity.to_array().map(|v| v as f32));
            moving.push(flow[i].iter().map(|v| v * v).sum::<f32>().sqrt() > MOVING_SPEED);
        }
    }
    let velocities = map.flow.as_ref().and(seconds_per_frame).map(|_| velocities);
    Ok(Some(DepthFlowSamples { pixels, depths, velocities, moving }))
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use dggt_data::{open_scene, prepare_view};
    use dggt_geom::glam::{DVec2, DVec3};

    use super::*;

    /// Relative depth mismatch, per moving cell of `frame`, between where the cell's surface point lands one
    /// frame later (moved by `velocity_gain` times its converted flow) and the next frame's measured depth
    /// there.
    fn landing_errors(scene: &Scene, preprocess: &Preprocess, frame: usize, velocity_gain: f64) -> Vec<f64> {
        let [now, next] = [frame, frame + 1].map(|f| prepare_view(scene, f, 0, preprocess).unwrap());
        let [here, there] = [&now, &next].map(|v| depth_flow_samples(scene, preprocess, v).unwrap().unwrap());
        let width = now.image.size.width as i64;
        let pixel = |index: i64| DVec2::new((index % width) as f64 + 0.5, (index / width) as f64 + 0.5);
        let velocities = here.velocities.as_ref().expect("a frame interval");
        let mut errors = Vec::new();
        for ((&index, &depth), velocity) in here.pixels.iter().zip(&here.depths).zip(velocities) {
            let velocity = DVec3::from_array(velocity.map(f64::from));
            // Faster than 1 m/s at 10 Hz.
            if velocity.length() < 0.1 {
                continue;
            }
            let moved = now.intrinsics.unproject(pixel(index), depth as f64) + velocity * velocity_gain;
            let in_next =
                next.world_from_camera.inverse().transform_point(now.world_from_camera.transform_point(moved));
            let Some(landing) = next.intrinsics.project(in_next) else { continue };
            let nearest = there
                .pixels
                .iter()
                .enumerate()
                .min_by(|(_, a), (_, b)| pixel(**a).distance(landing).total_cmp(&pixel(**b).distance(landing)))
                .filter(|(_, p)| pixel(**p).distance(landing) < 3.0);
            if let Some((i, _)) = nearest {
                errors.push((there.depths[i] as f64 - in_next.z).abs() / in_next.z);
            }
        }
        errors
    }

    fn median(mut values: Vec<f64>) -> f64 {
        values.sort_by(f64::total_cmp);
        values[values.len() / 2]
    }

    #[test]
    fn converted_flow_carries_moving_surfaces_to_the_next_frame() {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data-fixtures/synth-s0");
        let scene = open_scene(&root, Some(2..14), Some(vec![0])).unwrap();
        let preprocess = Preprocess { target_width: 168, patch_size: 14, crop_to_square: true };
        let (mut moved, mut held) = (Vec::new(), Vec::new());
        for frame in [0, 4, 8] {
            moved.extend(landing_errors(&scene, &preprocess, frame, 1.0));
            held.extend(landing_errors(&scene, &preprocess, frame, 0.0));
        }
        assert!(moved.len() > 30, "{} moving cells", moved.len());
        let (moved, held) = (median(moved), median(held));
        assert!(moved < 0.03 && held > 3.0 * moved, "median depth mismatch {moved} moved, {held} held");
    }
}
