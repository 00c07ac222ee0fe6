//! The burn tensor op against the host functions it wraps: images, statistics and autodiff gradients are
//! bit-identical to `rasterize` / `rasterize_backward` (the image gradients of a weighted sum reach the op
//! exactly), and the gradients stay within the gsplat parity tolerance. Also per-view opacities, gradients only
//! for inputs that require them, and shape errors.

use burn::tensor::{Device, FloatDType, Tensor, TensorData};
use dggt_geom::ImageSize;
use dggt_splat::{
    CameraTensors, GaussianGrads, GaussianTensors, Opacities, OpacityTensor, RasterSettings, RenderSettings,
    RenderTensors, SplatError, ViewBatch, render, render_with_stats,
};

use crate::parity::{GRADIENT, Tensors, check_both, parity_dir};
use crate::scenes::{LossWeights, Rng, Scene, render_with_grads, view_at};

pub fn tensor<const D: usize>(values: &[f32], shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values.to_vec(), shape), device)
}

pub fn values<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor.into_data().try_into_vec::<f32>().unwrap()
}

pub fn gaussian_tensors(scene: &Scene, views: usize, device: &Device, require_grad: bool) -> GaussianTensors {
    let (n, k) = (scene.len(), scene.channels);
    let leaf = |t: Tensor<2>| if require_grad { t.require_grad() } else { t };
    GaussianTensors {
        means: leaf(tensor(&scene.means, [n, 3], device)),
        quats_wxyz: leaf(tensor(&scene.quats, [n, 4], device)),
        scales: leaf(tensor(&scene.scales, [n, 3], device)),
        opacities: match &scene.opacities {
            Opacities::Shared(v) => {
                let t = tensor(v, [n], device);
                OpacityTensor::Shared(if require_grad { t.require_grad() } else { t })
            }
            Opacities::PerView(v) => OpacityTensor::PerView(leaf(tensor(v, [views, n], device))),
        },
        colors: leaf(tensor(&scene.colors, [n, k], device)),
    }
}

pub fn camera_tensors(views: &ViewBatch, device: &Device) -> CameraTensors {
    let count = views.len();
    let mut viewmats = Vec::with_capacity(16 * count);
    let mut intrinsics = Vec::with_capacity(9 * count);
    for view in views.views() {
        viewmats.extend(view.world_to_camera.iter().flatten());
        viewmats.extend([0.0, 0.0, 0.0, 1.0]);
        intrinsics.extend([view.fx, 0.0, view.cx, 0.0, view.fy, view.cy, 0.0, 0.0, 1.0]);
    }
    CameraTensors {
        world_to_camera: tensor(&viewmats, [count, 4, 4], device),
        intrinsics: tensor(&intrinsics, [count, 3, 3], device),
        size: views.size(),
    }
}

/// `L = Σ colors·wc + Σ alpha·wa + Σ depth·wd` on tensors.
pub fn weighted_loss(images: &RenderTensors, weights: &LossWeights, device: &Device) -> Tensor<1> {
    let [v, h, w, k] = images.colors.dims();
    let colors = tensor(&weights.colors, [v, h, w, k], device);
    let alpha = tensor(&weights.alpha, [v, h, w], device);
    let depth = tensor(&weights.depth, [v, h, w], device);
    total(images.colors.clone() * colors) + total(images.alpha.clone() * alpha) + total(images.depth.clone() * depth)
}

/// The sum of all elements as a `[1]` tensor, through a sum along one dimension: burn's full-sum kernel uses
/// shared memory, which lavapipe (the CI device) cannot compile as CubeCL emits it.
fn total<const D: usize>(values: Tensor<D>) -> Tensor<1> {
    let count = values.shape().num_elements();
    values.reshape([count, 1]).sum_dim(0).reshape([1])
}

/// Renders `scene` with the tensor op on `device` (an autodiff device) and asserts that the images, the
/// statistics and every gradient equal the host functions' bit for bit. Returns the tensor gradients.
fn assert_matches_host(
    device: &Device,
    scene: &Scene,
    views: &ViewBatch,
    background: Option<Vec<f32>>,
    weights: &LossWeights,
) -> GaussianGrads {
    let host_settings = RasterSettings { background: background.clone(), ..RasterSettings::default() };
    let (forward, host) = render_with_grads(scene, views, &host_settings, weights);

    let gaussians = gaussian_tensors(scene, views.len(), device, true);
    let background = background.map(|b| tensor(&b, [b.len()], device).require_grad());
    let settings = RenderSettings { raster: RasterSettings::default(), background: background.clone() };
    let (images, stats) = render_with_stats(&gaussians, &camera_tensors(views, device), &settings).unwrap();
    assert_eq!(stats, forward.stats, "statistics as the host's");
    assert_eq!(values(images.colors.clone()), forward.images.colors, "colours as the host's");
    assert_eq!(values(images.alpha.clone()), forward.images.alpha, "alpha as the host's");
    assert_eq!(values(images.depth.clone()), forward.images.depth, "depth as the host's");

    let grads = weighted_loss(&images, weights, device).backward();
    let opacities = match &gaussians.opacities {
        OpacityTensor::Shared(t) => Opacities::Shared(values(t.grad(&grads).unwrap())),
        OpacityTensor::PerView(t) => {
            let grad = t.grad(&grads).unwrap();
            assert_eq!(grad.dims(), [views.len(), scene.len()], "one opacity gradient row per view");
            Opacities::PerView(values(grad))
        }
    };
    let tensor_grads = GaussianGrads {
        means: values(gaussians.means.grad(&grads).unwrap()),
        quats: values(gaussians.quats_wxyz.grad(&grads).unwrap()),
        scales: values(gaussians.scales.grad(&grads).unwrap()),
        opacities,
        colors: values(gaussians.colors.grad(&grads).unwrap()),
        background: background.map_or_else(|| host.background.clone(), |b| values(b.grad(&grads).unwrap())),
    };
    assert_eq!(tensor_grads, host, "the op's gradients are the host's");
    tensor_grads
}

pub fn per_view_scene(rng: &mut Rng, views: usize) -> Scene {
    let mut scene = Scene::random(rng, 60, 4, (0.05, 0.4));
    let mut per_view = rng.ranges(views * scene.len(), 0.02, 0.95);
    for k in (0..per_view.len()).step_by(7) {
        per_view[k] = 0.001;
    }
    scene.opacities = Opacities::PerView(per_view);
    scene
}

pub fn three_views(size: ImageSize) -> ViewBatch {
    let cameras = vec![
        view_at([0.0; 3], 0.0, size),
        view_at([0.4, 0.1, 0.3], 0.12, size),
        view_at([-0.5, -0.2, -0.4], -0.2, size),
    ];
    ViewBatch::new(cameras, size).unwrap()
}

#[test]
fn flex_op_equals_the_host_rasteriser_on_the_gsplat_parity_case() {
    let case = "case_b_300g_64x48_2cam";
    let dir = parity_dir().join(case);
    let inputs = Tensors::load(&dir.join("inputs.safetensors"));
    let outputs = Tensors::load(&dir.join("outputs.safetensors"));
    let shape = inputs.shape("W1");
    let size = ImageSize::new(shape[2] as u32, shape[1] as u32).unwrap();
    let views = ViewBatch::from_matrices(inputs.get("viewmats"), inputs.get("Ks"), size).unwrap();
    let scene = Scene {
        means: inputs.get("means").to_vec(),
        quats: inputs.get("quats").to_vec(),
        scales: inputs.get("scales").to_vec(),
        opacities: Opacities::Shared(inputs.get("opacities").to_vec()),
        colors: inputs.get("colors").to_vec(),
        channels: 3,
    };
    let weights = LossWeights {
        colors: inputs.get("W1").to_vec(),
        alpha: inputs.get("W2").to_vec(),
        depth: inputs.get("W3").to_vec(),
    };

    // Forward only, on a device without autodiff.
    let device = Device::flex();
    let gaussians = gaussian_tensors(&scene, views.len(), &device, false);
    let (images, stats) =
        render_with_stats(&gaussians, &camera_tensors(&views, &device), &RenderSettings::default()).unwrap();
    let forward = dggt_splat::rasterize(&scene.gaussians(), &views, &RasterSettings::default()).unwrap();
    assert_eq!(stats, forward.stats);
    assert_eq!(values(images.colors), forward.images.colors);
    assert_eq!(values(images.alpha), forward.images.alpha);
    assert_eq!(values(images.depth), forward.images.depth);

    let grads = assert_matches_host(&Device::flex().autodiff(), &scene, &views, None, &weights);
    let Opacities::Shared(grad_opacities) = &grads.opacities else { panic!("shared opacities give shared gradients") };
    let case = format!("{case} (tensor op)");
    check_both(&case, "grad_means", &grads.means, &outputs, GRADIENT);
    check_both(&case, "grad_quats", &grads.quats, &outputs, GRADIENT);
    check_both(&case, "grad_scales", &grads.scales, &outputs, GRADIENT);
    check_both(&case, "grad_opacities", grad_opacities, &outputs, GRADIENT);
    check_both(&case, "grad_colors", &grads.colors, &outputs, GRADIENT);
}

#[test]
fn per_view_opacities_and_background_get_gradients_through_autodiff() {
    let mut rng = Rng::new(3);
    let size = ImageSize::new(40, 32).unwrap();
    let views = three_views(size);
    let scene = per_view_scene(&mut rng, views.len());
    let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
    let grads =
        assert_matches_host(&Device::flex().autodiff(), &scene, &views, Some(vec![0.1, 0.2, 0.3, 0.4]), &weights);
    assert!(grads.opacities.values().iter().any(|g| *g != 0.0));
    assert!(grads.background.iter().all(|g| *g != 0.0));
}

#[test]
fn only_inputs_that_require_grad_get_gradients_and_untracked_calls_render() {
    let mut rng = Rng::new(5);
    let size = ImageSize::new(24, 20).unwrap();
    let views = ViewBatch::new(vec![view_at([0.0; 3], 0.0, size)], size).unwrap();
    let scene = Scene::random(&mut rng, 20, 3, (0.1, 0.3));
    let weights = LossWeights::random(&mut rng, 1, size, 3);
    let (forward, host) = render_with_grads(&scene, &views, &RasterSettings::default(), &weights);
    let device = Device::flex().autodiff();
    let cameras = camera_tensors(&views, &device);

    // Nothing tracked: the call keeps no state and still renders.
    let mut gaussians = gaussian_tensors(&scene, 1, &device, false);
    let images = render(&gaussians, &cameras, &RenderSettings::default()).unwrap();
    assert_eq!(values(images.colors), forward.images.colors);

    gaussians.colors = gaussians.colors.require_grad();
    let images = render(&gaussians, &cameras, &RenderSettings::default()).unwrap();
    let grads = weighted_loss(&images, &weights, &device).backward();
    assert_eq!(values(gaussians.colors.grad(&grads).unwrap()), host.colors);
    assert!(gaussians.means.grad(&grads).is_none());
    assert!(gaussians.scales.grad(&grads).is_none());
}

#[test]
fn wrong_shapes_element_types_and_settings_are_errors() {
    let mut rng = Rng::new(8);
    let size = ImageSize::new(16, 16).unwrap();
    let views = ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([0.1, 0.0, 0.0], 0.1, size)], size).unwrap();
    let scene = Scene::random(&mut rng, 10, 3, (0.1, 0.3));
    let device = Device::flex();
    let gaussians = gaussian_tensors(&scene, 2, &device, false);
    let cameras = camera_tensors(&views, &device);
    let settings = RenderSettings::default();

    let quats = GaussianTensors { quats_wxyz: tensor(&scene.quats[..30], [10, 3], &device), ..gaussians.clone() };
    let error = render(&quats, &cameras, &settings).unwrap_err();
    assert_eq!(
        error,
        SplatError::TensorShape { tensor: "quats_wxyz", expected: "[N, 4] with N = 10".into(), actual: vec![10, 3] }
    );
    assert_eq!(error.to_string(), "`quats_wxyz` has shape [10, 3], expected [N, 4] with N = 10");

    let opacities = GaussianTensors {
        opacities: OpacityTensor::PerView(tensor(&[0.5; 30], [3, 10], &device)),
        ..gaussians.clone()
    };
    let error = render(&opacities, &cameras, &settings).unwrap_err();
    assert!(matches!(error, SplatError::TensorShape { tensor: "opacities", .. }), "{error}");

    let intrinsics = CameraTensors { intrinsics: tensor(&[1.0; 24], [2, 3, 4], &device), ..cameras.clone() };
    let error = render(&gaussians, &intrinsics, &settings).unwrap_err();
    assert!(matches!(error, SplatError::TensorShape { tensor: "intrinsics", .. }), "{error}");

    let background = RenderSettings { background: Some(tensor(&[0.0; 4], [4], &device)), ..settings.clone() };
    let error = render(&gaussians, &cameras, &background).unwrap_err();
    assert!(matches!(error, SplatError::TensorShape { tensor: "background", .. }), "{error}");

    let doubles = GaussianTensors { scales: gaussians.scales.clone().cast(FloatDType::F64), ..gaussians.clone() };
    let error = render(&doubles, &cameras, &settings).unwrap_err();
    assert_eq!(error, SplatError::ElementType { tensor: "scales", actual: "F64".into() });

    let twice = RenderSettings {
        raster: RasterSettings { background: Some(vec![0.0; 3]), ..RasterSettings::default() },
        ..settings.clone()
    };
    assert!(matches!(render(&gaussians, &cameras, &twice), Err(SplatError::InvalidSettings { .. })));
    let tiles =
        RenderSettings { raster: RasterSettings { tile_size: 0, ..RasterSettings::default() }, ..settings.clone() };
    assert!(matches!(render(&gaussians, &cameras, &tiles), Err(SplatError::InvalidSettings { .. })));

    // Camera values: a NaN focal length and a non-homogeneous view matrix are errors, not failures in the op.
    let mut k = values(cameras.intrinsics.clone());
    k[0] = f32::NAN;
    let nan_focal = CameraTensors { intrinsics: tensor(&k, [2, 3, 3], &device), ..cameras.clone() };
    let error = render(&gaussians, &nan_focal, &settings).unwrap_err();
    assert!(matches!(error, SplatError::InvalidView { .. }), "{error}");
    let mut m = values(cameras.world_to_camera.clone());
    m[16 + 12] = 0.5;
    let bad_view = CameraTensors { world_to_camera: tensor(&m, [2, 4, 4], &device), ..cameras };
    let error = render(&gaussians, &bad_view, &settings).unwrap_err();
    assert!(matches!(error, SplatError::InvalidView { .. }), "{error}");
}

#[cfg(feature = "ndarray")]
#[test]
fn ndarray_op_equals_the_host_rasteriser() {
    let mut rng = Rng::new(4);
    let size = ImageSize::new(40, 32).unwrap();
    let views = three_views(size);
    let scene = per_view_scene(&mut rng, views.len());
    let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
    #[allow(deprecated)]
    let device = Device::ndarray().autodiff();
    assert_matches_host(&device, &scene, &views, Some(vec![0.3, 0.2, 0.1, 0.0]), &weights);
}
