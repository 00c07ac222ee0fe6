//! The flow head taught by scene flow alone (`loss.learnt_flow`): a patch slides two pixels to the right between
//! two views of a camera turned about its vertical axis; its pixels carry features that say where in the patch
//! they lie, the same at both times. Adam on the head's parameters alone brings the loss down, and the head's
//! velocities come out in the flow's axes and units (camera axes, world units per log frame), forward from the
//! first view and back from the second.

use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use dggt_flow_head::{FlowHead, FlowHeadConfig, FlowHeadShape};
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{ImageSize, PinholeIntrinsics, PixelConvention, PosedCamera, WorldFromCamera};
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_objective::{DepthFlowSamples, StepBatch, ViewTruth, learnt_flow_loss};
use dggt_scene::{Axes, InputView, MeansGradient, PixelGaussians, Timeline};

const W: usize = 16;
const H: usize = 12;
/// Pixels the patch moves to the right from view 0 to view 1.
const SHIFT: usize = 2;
/// Depth of the patch (the background is twice as far).
const DEPTH: f32 = 4.0;
const FOCAL: f64 = 20.0;

fn in_patch(view: usize, column: usize, row: usize) -> bool {
    (4..8).contains(&row) && (3 + SHIFT * view..8 + SHIFT * view).contains(&column)
}

fn camera() -> PosedCamera {
    let turned = DQuat::from_rotation_y(0.5);
    PosedCamera {
        world_from_camera: WorldFromCamera::from_rotation_translation(turned, DVec3::new(1.0, 0.0, -2.0)).unwrap(),
        intrinsics: PinholeIntrinsics::new(FOCAL, FOCAL, W as f64 / 2.0, H as f64 / 2.0).unwrap(),
    }
}

/// The two views' Gaussians: the patch dynamic at `DEPTH`, the rest static behind it.
fn pixels(timeline: &Timeline, device: &Device) -> PixelGaussians {
    let (mut depth, mut logit) = (Vec::new(), Vec::new());
    for view in 0..2 {
        for row in 0..H {
            for column in 0..W {
                let patch = in_patch(view, column, row);
                depth.push(if patch { DEPTH } else { 2.0 * DEPTH });
                logit.push(if patch { 8.0 } else { -8.0 });
            }
        }
    }
    let maps = GaussianMaps::from_raw(Tensor::zeros([1, 2, H, W, 12], device));
    let depth = Tensor::from_data(TensorData::new(depth, [1, 2, H, W]), device);
    let logit = Tensor::from_data(TensorData::new(logit, [1, 2, H, W]), device);
    let views =
        [0.0, 4.0].map(|frame| InputView { rig_camera: 0, time: timeline.time(frame), camera: camera() }).to_vec();
    PixelGaussians::new(&maps, depth, Some(logit), views, MeansGradient::Detached, PixelConvention::Centred).unwrap()
}

/// Each pixel's place in the patch (column and row from its left and top edge, over 4) and a constant.
fn features(device: &Device) -> Vec<Tensor<4>> {
    let mut values = vec![0.0f32; 2 * 3 * H * W];
    for view in 0..2 {
        for row in 0..H {
            for column in 0..W {
                let at = |channel: usize| ((view * 3 + channel) * H + row) * W + column;
                values[at(0)] = (column as f32 - (3 + SHIFT * view) as f32) / 4.0;
                values[at(1)] = (row as f32 - 4.0) / 4.0;
                values[at(2)] = 1.0;
            }
        }
    }
    vec![Tensor::from_data(TensorData::new(values, [2, 3, H, W]), device)]
}

/// The true velocity of the patch in the camera's axes, world units per log frame: `SHIFT` pixels at `DEPTH`
/// over the four frames between the views.
fn patch_velocity() -> [f32; 3] {
    [(SHIFT as f64 * f64::from(DEPTH) / FOCAL / 4.0) as f32, 0.0, 0.0]
}

/// Both views as a batch whose flow samples are every pixel: the patch moving, the rest still.
fn batch(timeline: &Timeline, device: &Device) -> StepBatch {
    let view = |index: usize| {
        let pixels: Vec<i64> = (0..(H * W) as i64).collect();
        let moving: Vec<bool> = (0..H * W).map(|p| in_patch(index, p % W, p / W)).collect();
        let velocities = moving.iter().map(|&m| if m { patch_velocity() } else { [0.0; 3] }).collect();
        ViewTruth {
            frame: 4 * index,
            rig_camera: 0,
            time: timeline.time(4.0 * index as f64),
            camera: camera(),
            image: Tensor::zeros([H, W, 3], device),
            sky: None,
            dynamic: None,
            depth_flow: Some(DepthFlowSamples {
                pixels,
                depths: vec![DEPTH; H * W],
                velocities: Some(velocities),
                moving,
            }),
        }
    };
    StepBatch {
        step: 0,
        images: Tensor::zeros([1, 2, 3, H, W], device),
        size: ImageSize::new(W as u32, H as u32).unwrap(),
        timeline: *timeline,
        inputs: vec![view(0), view(1)],
        targets: Vec::new(),
    }
}

fn loss(head: &FlowHead, pixels: &PixelGaussians, batch: &StepBatch, device: &Device) -> Tensor<1> {
    let moved = pixels.clone().with_learnt_flow(head, &features(device)).unwrap();
    learnt_flow_loss(&moved, batch).unwrap().expect("the head moved rows with flow samples")
}

#[test]
fn scene_flow_alone_teaches_the_flow_head() {
    let device = Device::flex().autodiff();
    let timeline = Timeline::new(&[0, 4]).unwrap();
    let (pixels, batch) = (pixels(&timeline, &device), batch(&timeline, &device));
    let config = FlowHeadConfig {
        feature_widths: vec![3],
        shape: FlowHeadShape { hidden: 16, heads: 2, neighbours: 6, iterations: 2, ..FlowHeadShape::default() },
    };
    let mut head = config.init(&device).unwrap();
    let value = |loss: Tensor<1>| loss.into_scalar::<f32>();
    // A fresh head holds: the loss is the patch's mean absolute velocity component.
    let initial = value(loss(&head, &pixels, &batch, &device));
    let expected = patch_velocity().iter().map(|v| v.abs()).sum::<f32>() / 3.0;
    assert!((initial - expected).abs() < 1e-6, "{initial} vs {expected}");
    let mut optimizer = AdamConfig::new().init();
    for _ in 0..150 {
        let grads = GradientsParams::from_grads(loss(&head, &pixels, &batch, &device).backward(), &head);
        head = optimizer.step(3e-3, head, grads);
    }
    let trained = value(loss(&head, &pixels, &batch, &device));
    assert!(trained < 0.25 * initial, "the learnt flow loss went from {initial} to {trained}");

    // Forward from view 0 and back from view 1, the head's velocities meet the patch's in the camera's axes. The
    // optimisation's path depends on the order of the CPU backend's parallel sums: over runs on two cores the
    // rows' mean L1 error was 0.003-0.007 and the worst row's 0.006-0.032 (of a velocity of 0.1), so the bounds
    // keep about twice the largest seen.
    let moved = pixels.with_learnt_flow(&head, &features(&device)).unwrap();
    let learnt = moved.learnt_velocity().unwrap();
    let per_frame =
        moved.rotate_rows(learnt.velocity, Axes::WorldToCamera).div_scalar(timeline.frames_per_time() as f32);
    let rows = per_frame.into_data().try_into_vec::<f32>().unwrap();
    let truth = patch_velocity();
    let errors: Vec<f32> = rows
        .chunks_exact(3)
        .enumerate()
        .filter(|&(row, _)| learnt.measured[row])
        .map(|(_, velocity)| (0..3).map(|i| (velocity[i] - truth[i]).abs()).sum())
        .collect();
    let mean = errors.iter().sum::<f32>() / errors.len() as f32;
    assert!(mean < 0.15 * truth[0], "mean L1 error {mean} of the measured rows against {truth:?}");
    let worst = errors.iter().copied().fold(0.0f32, f32::max);
    assert!(worst < 0.6 * truth[0], "the worst measured row is off by {worst} against {truth:?}");
}
