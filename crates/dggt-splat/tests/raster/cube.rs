//! The CubeCL rasteriser on burn's wgpu device against the host implementation (and so against gsplat): the
//! three shared parity cases, random scenes with per-view opacities and a background, an empty scene, and
//! non-finite or degenerate Gaussians.
//!
//! The kernels project in `f32` where the host uses `f64` and add gradients with atomics in no fixed order, so
//! the comparison uses tolerances: images those of the gsplat parity test, gradients the relative 1e-3 the parity
//! vectors recommend, against both the host and the gsplat references. Each comparison prints the error it
//! reached.
//!
//! These tests need a wgpu adapter; on a machine without a GPU, Mesa's software Vulkan driver (lavapipe,
//! Debian's `mesa-vulkan-drivers`) provides one. Without any adapter they fail: they never skip.

use std::panic::{AssertUnwindSafe, catch_unwind};

use burn::tensor::{Device, DeviceKind, Tensor, TensorData};
use dggt_geom::ImageSize;
use dggt_splat::{
    CullStats, GaussianGrads, Opacities, OpacityTensor, RasterSettings, RenderSettings, ViewBatch, rasterize,
    rasterize_backward, render, render_with_stats,
};

use crate::parity::{DEPTH, IMAGE, Tensors, Tolerance, check, check_both, compare, parity_dir};
use crate::scenes::{LossWeights, Rng, Scene, view_at};
use crate::tensor_op::{camera_tensors, gaussian_tensors, per_view_scene, tensor, three_views, values, weighted_loss};

/// Gradients: the relative tolerance the parity vectors recommend (1e-3 of the largest reference magnitude).
/// Measured on lavapipe: at most 4.4e-4 (case b quaternions, where the host's `f64` and gsplat's `f32` differ
/// as much), below 5e-5 elsewhere. Atomic accumulation makes the last bits vary from run to run.
const GRADIENT: Tolerance = Tolerance { atol: 1e-5, rtol: 1e-3 };

/// The CubeCL device the tests run on, checked to work: burn's default wgpu device, or the first CUDA device where
/// the environment variable `DGGT_TEST_DEVICE` is `cuda` (a build with the `cuda` feature; one kernel set serves
/// both). A clear failure when no device can be created.
pub fn cube_device() -> Device {
    let device = match std::env::var("DGGT_TEST_DEVICE").as_deref() {
        #[cfg(feature = "cuda")]
        Ok("cuda") => Device::cuda(0),
        Ok(other) if other != "wgpu" => {
            panic!("DGGT_TEST_DEVICE={other}: this test build runs `wgpu` (or `cuda` with the `cuda` feature)")
        }
        _ => Device::wgpu(DeviceKind::DefaultDevice),
    };
    let probe = catch_unwind(AssertUnwindSafe(|| {
        let t = Tensor::<1>::from_data(TensorData::new(vec![1.0f32, 2.0], [2]), &device);
        (t * 2.0).into_data().try_into_vec::<f32>()
    }));
    match probe {
        Ok(Ok(v)) if v == [2.0, 4.0] => device,
        other => panic!(
            "no usable CubeCL device {device:?} (got {:?}). These tests need a GPU or a software Vulkan driver: \
             install Mesa's lavapipe (`apt-get install mesa-vulkan-drivers`).",
            other.as_ref().map(|r| r.as_ref().map(|_| ()).map_err(|e| format!("{e:?}"))).map_err(|_| "panic")
        ),
    }
}

/// What one wgpu render and its backward pass produced, as host buffers.
pub struct DeviceResult {
    pub colors: Vec<f32>,
    pub alpha: Vec<f32>,
    pub depth: Vec<f32>,
    pub stats: Vec<CullStats>,
    pub grads: GaussianGrads,
}

/// Renders `scene` on `device` (an autodiff device), differentiates the weighted loss and reads everything back.
fn render_on(
    device: &Device,
    scene: &Scene,
    views: &ViewBatch,
    background: Option<&[f32]>,
    weights: &LossWeights,
) -> DeviceResult {
    render_on_with(device, scene, views, background, weights, &RasterSettings::default())
}

/// [`render_on`] with the given raster settings.
pub fn render_on_with(
    device: &Device,
    scene: &Scene,
    views: &ViewBatch,
    background: Option<&[f32]>,
    weights: &LossWeights,
    raster: &RasterSettings,
) -> DeviceResult {
    let gaussians = gaussian_tensors(scene, views.len(), device, true);
    let background = background.map(|b| tensor(b, [b.len()], device).require_grad());
    let settings = RenderSettings { raster: raster.clone(), background: background.clone() };
    let (images, stats) = render_with_stats(&gaussians, &camera_tensors(views, device), &settings).unwrap();
    let grads = weighted_loss(&images, weights, device).backward();
    let opacities = match &gaussians.opacities {
        OpacityTensor::Shared(t) => Opacities::Shared(values(t.grad(&grads).expect("opacity gradient"))),
        OpacityTensor::PerView(t) => {
            let grad = t.grad(&grads).expect("opacity gradient");
            assert_eq!(grad.dims(), [views.len(), scene.len()], "one opacity gradient row per view");
            Opacities::PerView(values(grad))
        }
    };
    let grads = GaussianGrads {
        means: values(gaussians.means.grad(&grads).expect("means gradient")),
        quats: values(gaussians.quats_wxyz.grad(&grads).expect("quats gradient")),
        scales: values(gaussians.scales.grad(&grads).expect("scales gradient")),
        opacities,
        colors: values(gaussians.colors.grad(&grads).expect("colours gradient")),
        background: match &background {
            Some(b) => values(b.grad(&grads).expect("background gradient")),
            None => vec![],
        },
    };
    DeviceResult {
        colors: values(images.colors),
        alpha: values(images.alpha),
        depth: values(images.depth),
        stats,
        grads,
    }
}

/// Compares a device result with the host forward and backward of the same scene; returns the host gradients.
pub fn assert_close_to_host(
    case: &str,
    result: &DeviceResult,
    scene: &Scene,
    views: &ViewBatch,
    background: Option<&[f32]>,
    weights: &LossWeights,
) -> GaussianGrads {
    assert_close_to_host_with(case, result, scene, views, background, weights, &RasterSettings::default())
}

/// [`assert_close_to_host`] for a render with the given raster settings.
pub fn assert_close_to_host_with(
    case: &str,
    result: &DeviceResult,
    scene: &Scene,
    views: &ViewBatch,
    background: Option<&[f32]>,
    weights: &LossWeights,
    raster: &RasterSettings,
) -> GaussianGrads {
    let settings = RasterSettings { background: background.map(<[f32]>::to_vec), ..raster.clone() };
    let gaussians = scene.gaussians();
    let forward = rasterize(&gaussians, views, &settings).unwrap();
    let host =
        rasterize_backward(&gaussians, views, &settings, &forward, &weights.image_grads_for(settings.depth)).unwrap();
    let all = |_| true;
    check(case, "colors vs host", compare(&result.colors, &forward.images.colors, all), IMAGE);
    check(case, "alpha vs host", compare(&result.alpha, &forward.images.alpha, all), IMAGE);
    check(case, "depth vs host", compare(&result.depth, &forward.images.depth, all), DEPTH);
    for (v, (ours, theirs)) in result.stats.iter().zip(&forward.stats).enumerate() {
        // Rounding of a footprint radius or tile boundary may add or drop a tile intersection; the culling
        // decisions themselves must agree.
        let without_tiles = |s: &CullStats| CullStats { tile_intersections: 0, ..*s };
        assert_eq!(without_tiles(ours), without_tiles(theirs), "{case}: view {v} statistics");
        let (a, b) = (ours.tile_intersections as f64, theirs.tile_intersections as f64);
        assert!((a - b).abs() <= 0.01 * b + 2.0, "{case}: view {v}: {a} vs {b} tile intersections");
        eprintln!("{case:<28} view {v}: {ours}");
    }
    assert_eq!(result.stats.len(), forward.stats.len(), "{case}: statistics per view");
    let grad = |name: &str, ours: &[f32], theirs: &[f32]| {
        check(case, &format!("{name} vs host"), compare(ours, theirs, all), GRADIENT);
    };
    grad("grad means", &result.grads.means, &host.means);
    grad("grad quats", &result.grads.quats, &host.quats);
    grad("grad scales", &result.grads.scales, &host.scales);
    assert_eq!(
        matches!(result.grads.opacities, Opacities::PerView(_)),
        matches!(host.opacities, Opacities::PerView(_)),
        "{case}: opacity gradient shape"
    );
    grad("grad opacities", result.grads.opacities.values(), host.opacities.values());
    grad("grad colors", &result.grads.colors, &host.colors);
    if background.is_some() {
        let tolerance = Tolerance { atol: 1e-4, rtol: 1e-5 };
        check(case, "grad background vs host", compare(&result.grads.background, &host.background, all), tolerance);
    }
    host
}

#[test]
fn wgpu_matches_the_host_and_gsplat_on_the_shared_reference_cases() {
    let device = cube_device().autodiff();
    for case in ["case_a_50g_32x24_1cam", "case_b_300g_64x48_2cam", "case_c_80g_40x40_degenerate"] {
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
        let result = render_on(&device, &scene, &views, None, &weights);
        let label = format!("{case} (wgpu)");
        assert_close_to_host(&label, &result, &scene, &views, None, &weights);

        check_both(&label, "render_rgb", &result.colors, &outputs, IMAGE);
        check_both(&label, "render_alpha", &result.alpha, &outputs, IMAGE);
        check_both(&label, "render_depth_ed", &result.depth, &outputs, DEPTH);
        let Opacities::Shared(grad_opacities) = &result.grads.opacities else {
            panic!("shared opacities give shared gradients")
        };
        check_both(&label, "grad_means", &result.grads.means, &outputs, GRADIENT);
        check_both(&label, "grad_quats", &result.grads.quats, &outputs, GRADIENT);
        check_both(&label, "grad_scales", &result.grads.scales, &outputs, GRADIENT);
        check_both(&label, "grad_opacities", grad_opacities, &outputs, GRADIENT);
        check_both(&label, "grad_colors", &result.grads.colors, &outputs, GRADIENT);
    }
}

#[test]
fn wgpu_matches_the_host_with_per_view_opacities_and_a_background() {
    let device = cube_device().autodiff();
    for seed in [3, 11] {
        let mut rng = Rng::new(seed);
        let size = ImageSize::new(40, 32).unwrap();
        let views = three_views(size);
        let scene = per_view_scene(&mut rng, views.len());
        let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
        let background = [0.1, 0.2, 0.3, 0.4];
        let result = render_on(&device, &scene, &views, Some(&background), &weights);
        let host = assert_close_to_host(
            &format!("per-view seed {seed}"),
            &result,
            &scene,
            &views,
            Some(&background),
            &weights,
        );
        assert!(host.opacities.values().iter().any(|g| *g != 0.0));
    }
}

#[test]
fn wgpu_renders_shared_opacities_at_an_odd_size_with_small_tiles() {
    // A size that is no multiple of the tile size, and many Gaussians per tile.
    let device = cube_device().autodiff();
    let mut rng = Rng::new(21);
    let size = ImageSize::new(37, 23).unwrap();
    let views =
        ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([0.3, 0.1, -0.2], -0.15, size)], size).unwrap();
    let scene = Scene::random(&mut rng, 150, 3, (0.05, 0.5));
    let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
    let result = render_on(&device, &scene, &views, Some(&[0.5, 0.5, 0.5]), &weights);
    assert_close_to_host("shared 37x23", &result, &scene, &views, Some(&[0.5, 0.5, 0.5]), &weights);
}

#[test]
fn wgpu_renders_an_empty_scene_as_the_background() {
    let device = cube_device().autodiff();
    let size = ImageSize::new(19, 13).unwrap();
    let views = ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([1.0, 0.0, 0.0], 0.3, size)], size).unwrap();
    let scene = Scene {
        means: vec![],
        quats: vec![],
        scales: vec![],
        opacities: Opacities::Shared(vec![]),
        colors: vec![],
        channels: 3,
    };
    let weights = LossWeights::random(&mut Rng::new(1), 2, size, 3);
    let background = [0.1, 0.2, 0.3];
    let result = render_on(&device, &scene, &views, Some(&background), &weights);
    let pixels = 2 * size.area();
    assert_eq!(result.colors, background.repeat(pixels));
    assert_eq!(result.alpha, vec![0.0; pixels]);
    assert_eq!(result.depth, vec![0.0; pixels]);
    assert!(result.stats.iter().all(|s| *s == CullStats::default()));
    assert!(result.grads.means.is_empty() && result.grads.colors.is_empty());
    for k in 0..3 {
        let expected: f64 = weights.colors.iter().skip(k).step_by(3).map(|g| *g as f64).sum();
        assert!((result.grads.background[k] as f64 - expected).abs() < 1e-3, "background {k}");
    }
}

#[test]
fn wgpu_renders_no_views() {
    let device = cube_device();
    let size = ImageSize::new(8, 8).unwrap();
    let views = ViewBatch::new(vec![], size).unwrap();
    let scene = Scene::random(&mut Rng::new(2), 5, 3, (0.1, 0.2));
    let gaussians = gaussian_tensors(&scene, 0, &device, false);
    let (images, stats) =
        render_with_stats(&gaussians, &camera_tensors(&views, &device), &RenderSettings::default()).unwrap();
    assert_eq!(images.colors.dims(), [0, 8, 8, 3]);
    assert!(values(images.alpha).is_empty() && stats.is_empty());
}

#[test]
fn wgpu_culls_non_finite_and_degenerate_gaussians_without_nan() {
    let device = cube_device().autodiff();
    let mut rng = Rng::new(17);
    let size = ImageSize::new(32, 24).unwrap();
    let views =
        ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([0.5, -0.2, 0.1], 0.25, size)], size).unwrap();
    let mut scene = Scene::random(&mut rng, 40, 3, (0.05, 0.4));
    scene.means[0] = f32::NAN;
    scene.quats[4] = f32::INFINITY;
    scene.scales[6] = f32::NAN;
    scene.colors[9] = f32::NEG_INFINITY;
    // Zero quaternion (identity), zero scales (eps2d blur only), huge and tiny scales, a needle.
    scene.quats[16..20].copy_from_slice(&[0.0; 4]);
    scene.scales[15..18].copy_from_slice(&[0.0; 3]);
    scene.scales[18..21].copy_from_slice(&[1e3, 1e3, 1e3]);
    scene.scales[21..24].copy_from_slice(&[1e-30, 1e-30, 1e-30]);
    scene.scales[24..27].copy_from_slice(&[0.3, 1e-7, 1e-7]);
    // Behind the camera, on the near plane, far beyond the image.
    scene.means[27..30].copy_from_slice(&[0.0, 0.0, -2.0]);
    scene.means[30..33].copy_from_slice(&[0.0, 0.0, 0.01]);
    scene.means[33..36].copy_from_slice(&[500.0, 0.0, 3.0]);
    let Opacities::Shared(opacities) = &mut scene.opacities else { unreachable!() };
    opacities[12] = f32::NAN;
    opacities[13] = 0.001;
    opacities[14] = 1.0;
    let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
    let result = render_on(&device, &scene, &views, Some(&[0.2, 0.1, 0.0]), &weights);
    for (name, values) in [("colors", &result.colors), ("alpha", &result.alpha), ("depth", &result.depth)] {
        assert!(values.iter().all(|v| v.is_finite()), "non-finite {name} image");
    }
    let g = &result.grads;
    for (name, values) in [
        ("means", g.means.as_slice()),
        ("quats", &g.quats),
        ("scales", &g.scales),
        ("opacities", g.opacities.values()),
        ("colors", &g.colors),
        ("background", &g.background),
    ] {
        assert!(values.iter().all(|v| v.is_finite()), "non-finite {name} gradient");
    }
    // Gaussians 0 (mean), 1 (quat), 2 (scale), 3 (colour) and 12 (opacity) are non-finite in both views.
    assert!(result.stats.iter().all(|s| s.non_finite == 5), "{:?}", result.stats);
    assert_close_to_host("degenerate", &result, &scene, &views, Some(&[0.2, 0.1, 0.0]), &weights);
}

#[test]
fn wgpu_forward_without_autodiff_matches_the_host() {
    let device = cube_device();
    let mut rng = Rng::new(5);
    let size = ImageSize::new(24, 20).unwrap();
    let views = ViewBatch::new(vec![view_at([0.0; 3], 0.0, size)], size).unwrap();
    let scene = Scene::random(&mut rng, 20, 3, (0.1, 0.3));
    let gaussians = gaussian_tensors(&scene, 1, &device, false);
    let images = render(&gaussians, &camera_tensors(&views, &device), &RenderSettings::default()).unwrap();
    let forward = rasterize(&scene.gaussians(), &views, &RasterSettings::default()).unwrap();
    let all = |_| true;
    check("forward only", "colors vs host", compare(&values(images.colors), &forward.images.colors, all), IMAGE);
    check("forward only", "alpha vs host", compare(&values(images.alpha), &forward.images.alpha, all), IMAGE);
    check("forward only", "depth vs host", compare(&values(images.depth), &forward.images.depth, all), DEPTH);
}

#[test]
fn wgpu_matches_the_host_on_a_dense_scene_with_coincident_gaussians() {
    // Thousands of small Gaussians per tile, as a pixel-aligned scene gives, and exact depth ties: a copy of
    // the first 3000 at the same positions with other opacities (the static and dynamic copies of a pixel).
    let device = cube_device().autodiff();
    let mut rng = Rng::new(5);
    let size = ImageSize::new(70, 56).unwrap();
    let views = ViewBatch::new(vec![view_at([0.0; 3], 0.0, size)], size).unwrap();
    let mut scene = Scene::random(&mut rng, 7500, 3, (0.003, 0.03));
    let copies = 3000;
    let Opacities::Shared(opacities) = &mut scene.opacities else { unreachable!() };
    let extra: Vec<f32> = rng.ranges(copies, 0.05, 0.95);
    opacities.extend(extra);
    let (means, quats, scales, colors) = (
        scene.means[..3 * copies].to_vec(),
        scene.quats[..4 * copies].to_vec(),
        scene.scales[..3 * copies].to_vec(),
        scene.colors[..3 * copies].to_vec(),
    );
    scene.means.extend(means);
    scene.quats.extend(quats);
    scene.scales.extend(scales);
    scene.colors.extend(colors);
    let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
    let forward = rasterize(&scene.gaussians(), &views, &RasterSettings::default()).unwrap();
    let longest = forward.bins[0].offsets.windows(2).map(|w| w[1] - w[0]).max().unwrap();
    assert!(longest > 3500, "the scene should give long tile lists, the longest has {longest}");
    let result = render_on(&device, &scene, &views, None, &weights);
    assert_close_to_host("dense 70x56", &result, &scene, &views, None, &weights);
}
