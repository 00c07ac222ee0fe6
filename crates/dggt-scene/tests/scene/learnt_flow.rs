//! Dynamic Gaussians moved along the flow head's learnt displacements, on the sliding patch of `common`: a fresh
//! head holds every Gaussian; a trained one moves each input's dynamic rows by the fraction of the step to the
//! neighbouring input, returns the inputs' Gaussians exactly at their own times, is trained by renders between
//! them, and is not run for a pair of inputs in which one has no dynamic pixel.

use burn::module::Module;
use burn::nn::LinearConfig;
use burn::tensor::{Device, Tensor, TensorData};
use dggt_flow_head::{FlowHead, FlowHeadConfig, FlowHeadShape};
use dggt_scene::{
    AssemblySettings, DynamicBlend, DynamicMotion, PixelGaussians, TargetView, assemble, assembled_velocities,
    interpolate_camera, render_target,
};

use crate::common::{H, S, W, in_patch, pixels};

/// Two feature scales: half resolution with 4 channels, full resolution with 3.
const WIDTHS: [usize; 2] = [4, 3];

fn config() -> FlowHeadConfig {
    FlowHeadConfig {
        feature_widths: WIDTHS.to_vec(),
        shape: FlowHeadShape {
            hidden: 16,
            heads: 2,
            neighbours: 6,
            iterations: 2,
            chunk: 64,
            ..FlowHeadShape::default()
        },
    }
}

/// A head whose last layer is no longer zero, so that it predicts a displacement.
fn moving_head(device: &Device) -> FlowHead {
    let mut head = config().init(device).unwrap();
    head.update.fc2 = LinearConfig::new(16, 3).init(device);
    head
}

/// Deterministic feature maps of every view, `[S, C, h, w]` per scale.
fn features(device: &Device) -> Vec<Tensor<4>> {
    let map = |channels: usize, h: usize, w: usize, seed: u64| {
        let values: Vec<f32> =
            (0..S * channels * h * w).map(|i| ((i as u64 * 2654435761 + seed) % 1000) as f32 / 500.0 - 1.0).collect();
        Tensor::<4>::from_data(TensorData::new(values, [S, channels, h, w]), device)
    };
    vec![map(WIDTHS[0], H / 2, W / 2, 3), map(WIDTHS[1], H, W, 5)]
}

fn host<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor.into_data().try_into_vec::<f32>().unwrap()
}

fn target(pixels: &PixelGaussians, time: f64) -> TargetView {
    TargetView { rig_camera: 0, time, camera: interpolate_camera(&pixels.views, 0, time).unwrap() }
}

fn settings(motion: DynamicMotion, blend: DynamicBlend) -> AssemblySettings {
    AssemblySettings { dynamic_motion: motion, dynamic_blend: blend, ..AssemblySettings::exact() }
}

fn means(pixels: &PixelGaussians, time: f64, settings: &AssemblySettings) -> Vec<f32> {
    host(assemble(pixels, &target(pixels, time), settings).unwrap().gaussians.means)
}

#[test]
fn a_fresh_head_holds_every_gaussian() {
    let device = Device::flex();
    let head = config().init(&device).unwrap();
    let pixels = pixels(&device).with_learnt_flow(&head, &features(&device)).unwrap();
    let flow = pixels.learnt().expect("the learnt flow is kept");
    assert!(host(flow.to_next.clone()).iter().chain(&host(flow.to_previous.clone())).all(|&v| v == 0.0));
    for blend in [DynamicBlend::Nearest, DynamicBlend::CrossFade] {
        let held = means(&pixels, 0.2, &settings(DynamicMotion::Held, blend));
        assert_eq!(means(&pixels, 0.2, &settings(DynamicMotion::Learnt, blend)), held);
    }
}

#[test]
fn the_learnt_flow_moves_a_fraction_of_each_step_and_leaves_the_inputs_exact() {
    let device = Device::flex();
    let pixels = pixels(&device).with_learnt_flow(&moving_head(&device), &features(&device)).unwrap();
    let flow = pixels.learnt().unwrap();
    let (next, previous) = (host(flow.to_next.clone()), host(flow.to_previous.clone()));
    let per_view = H * W;
    for view in 0..S {
        for pixel in 0..per_view {
            let row = view * per_view + pixel;
            let moving = |values: &[f32]| values[3 * row..3 * row + 3].iter().any(|&v| v != 0.0);
            let patch = in_patch(view, pixel % W, pixel / W);
            // The patch's rows have a next input but the last view's; a previous one but the first view's.
            assert_eq!(moving(&next), patch && view + 1 < S, "to next, view {view} pixel {pixel}");
            assert_eq!(moving(&previous), patch && view > 0, "to previous, view {view} pixel {pixel}");
        }
    }
    // Nearest at 0.2: view 0 (time 0) moved 0.4 of its step to view 1 (time 0.5); the static union first.
    let statics = S * per_view * 3;
    let held = means(&pixels, 0.2, &settings(DynamicMotion::Held, DynamicBlend::Nearest));
    let moved = means(&pixels, 0.2, &settings(DynamicMotion::Learnt, DynamicBlend::Nearest));
    assert_eq!(held[..statics], moved[..statics], "static Gaussians do not move");
    // Every row of view 0 is drawn (no culling); each moves by 0.4 of its displacement (zero off the patch).
    assert_eq!(moved.len(), statics + 3 * per_view);
    for pixel in 0..per_view {
        for axis in 0..3 {
            let expected = held[statics + 3 * pixel + axis] + 0.4 * next[3 * pixel + axis];
            assert!((moved[statics + 3 * pixel + axis] - expected).abs() < 1e-5, "pixel {pixel} axis {axis}");
        }
    }
    // At an input's own time (w = 0 for its view, nothing else drawn) the input's Gaussians exactly.
    for (time, blend) in [(0.5, DynamicBlend::Nearest), (1.0, DynamicBlend::CrossFade), (0.0, DynamicBlend::CrossFade)]
    {
        let held = means(&pixels, time, &settings(DynamicMotion::Held, blend));
        assert_eq!(means(&pixels, time, &settings(DynamicMotion::Learnt, blend)), held, "t = {time}");
    }
    // The velocity of a row at 0.2 is its displacement over the step's time (0.5).
    let at = target(&pixels, 0.2);
    let velocities =
        assembled_velocities(&pixels, &at, &settings(DynamicMotion::Learnt, DynamicBlend::Nearest)).unwrap();
    let first = (0..per_view).find(|&p| in_patch(0, p % W, p / W)).unwrap();
    for axis in 0..3 {
        assert!((velocities[S * per_view + first][axis] - next[3 * first + axis] / 0.5).abs() < 1e-5);
    }
    let inputs = pixels.learnt_velocities().unwrap();
    assert_eq!(inputs[first], velocities[S * per_view + first]);
    let last = 2 * per_view + (0..per_view).find(|&p| in_patch(2, p % W, p / W)).unwrap();
    for axis in 0..3 {
        assert!((inputs[last][axis] + previous[3 * last + axis] / 0.5).abs() < 1e-5, "the last input looks back");
    }
}

#[test]
fn the_learnt_velocity_tensor_is_the_host_velocities_and_marks_the_rows_the_head_moved() {
    let device = Device::flex().autodiff();
    let head = moving_head(&device);
    let pixels = pixels(&device).with_learnt_flow(&head, &features(&device)).unwrap();
    let learnt = pixels.learnt_velocity().expect("a learnt flow has velocities");
    let expected: Vec<f32> = pixels.learnt_velocities().unwrap().into_iter().flatten().collect();
    let values = host(learnt.velocity.clone());
    assert!(values.iter().zip(&expected).all(|(a, b)| (a - b).abs() < 1e-6));
    // Views 0 and 1 read their velocity off the step to the next input, view 2 (the last) off the one back:
    // every patch row was a query of the pair it reads, and only those.
    for (row, &measured) in learnt.measured.iter().enumerate() {
        let (view, pixel) = (row / (H * W), row % (H * W));
        assert_eq!(measured, in_patch(view, pixel % W, pixel / W), "row {row}");
    }
    let grads = learnt.velocity.abs().sum().backward();
    let weight = head.update.fc2.weight.val().grad(&grads).expect("the velocities reach the head");
    assert!(host(weight).iter().any(|&v| v != 0.0));

    // Without dynamic pixels in view 1 neither of its pairs runs: no row is measured.
    let mut still = pixels;
    let mut logits = host(still.dynamic_logit.clone().unwrap());
    logits[H * W..2 * H * W].fill(-8.0);
    still.dynamic_logit = Some(Tensor::from_data(TensorData::new(logits, [S * H * W]), &device));
    let still = still.with_learnt_flow(&head, &features(&device)).unwrap();
    assert!(!still.learnt_velocity().unwrap().measured.contains(&true));
}

#[test]
fn renders_between_the_inputs_train_the_head() {
    let device = Device::flex().autodiff();
    let head = config().init(&device).unwrap();
    let pixels = pixels(&device).with_learnt_flow(&head, &features(&device)).unwrap();
    let at = target(&pixels, 0.2);
    let view = render_target(&pixels, None, &at, &settings(DynamicMotion::Learnt, DynamicBlend::CrossFade)).unwrap();
    let grads = view.rgb.powi_scalar(2).sum().backward();
    let weight = head.update.fc2.weight.val().grad(&grads).expect("the head's last layer gets a gradient");
    let values = host(weight);
    assert!(values.iter().all(|v| v.is_finite()));
    assert!(values.iter().any(|&v| v != 0.0), "a render between the inputs trains the head");
}

#[test]
fn a_pair_without_dynamic_pixels_does_not_run_the_head() {
    let device = Device::flex();
    // Weights of NaN: running the head on any pair is an error naming the displacement.
    let broken = moving_head(&device).map(&mut NanWeights);
    let mut pixels = pixels(&device);
    let error = pixels.clone().with_learnt_flow(&broken, &features(&device)).unwrap_err().to_string();
    assert!(error.contains("learnt scene flow"), "{error}");
    // View 1 without dynamic pixels: both of its pairs are skipped, and every row keeps zero flow.
    let mut logits = host(pixels.dynamic_logit.clone().unwrap());
    logits[H * W..2 * H * W].fill(-8.0);
    pixels.dynamic_logit = Some(Tensor::from_data(TensorData::new(logits, [S * H * W]), &device));
    let still = pixels.with_learnt_flow(&broken, &features(&device)).unwrap();
    assert!(host(still.learnt().unwrap().to_next.clone()).iter().all(|&v| v == 0.0));
}

/// Sets every float parameter to NaN.
struct NanWeights;

impl burn::module::ModuleMapper for NanWeights {
    fn map_float<const D: usize>(&mut self, param: burn::module::Param<Tensor<D>>) -> burn::module::Param<Tensor<D>> {
        param.map(|tensor| tensor.mul_scalar(f32::NAN))
    }
}

#[test]
fn a_saved_scene_keeps_its_learnt_flow() {
    let device = Device::flex();
    let pixels = pixels(&device).with_learnt_flow(&moving_head(&device), &features(&device)).unwrap();
    let assembly = settings(DynamicMotion::Learnt, DynamicBlend::CrossFade);
    let scene = dggt_scene::Scene4d { pixels, sky: None, assembly };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.safetensors");
    dggt_scene::save_scene(&scene, &path).unwrap();
    let loaded = dggt_scene::load_scene(&path, &device).unwrap();
    let flow = loaded.pixels.learnt().expect("the learnt flow is read back");
    assert_eq!(host(flow.to_next.clone()), host(scene.pixels.learnt().unwrap().to_next.clone()));
    let at = target(&scene.pixels, 0.3);
    assert_eq!(host(loaded.render(&at).unwrap().rgb), host(scene.render(&at).unwrap().rgb));
}
