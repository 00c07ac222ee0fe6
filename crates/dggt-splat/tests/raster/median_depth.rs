//! The median depth: the surface a pixel sees rather than the blend of the surfaces along its ray. Two broad
//! Gaussians on the optical axis make the answer known in closed form; colours, alpha and gradients of a
//! median-depth render are those of an expected-depth one; a median depth takes no gradient (the host refuses
//! one, the tensor op detaches it); on wgpu the kernels agree with the host.

use burn::tensor::Device;
use dggt_geom::ImageSize;
use dggt_splat::{
    DepthStatistic, ImageGrads, Opacities, RasterSettings, RenderSettings, SplatError, ViewBatch, rasterize,
    rasterize_backward, render,
};

use crate::scenes::{LossWeights, Rng, Scene, render_with_grads, view_at};
use crate::tensor_op::{camera_tensors, gaussian_tensors, values, weighted_loss};

const SIZE: (u32, u32) = (20, 16);

/// Two isotropic Gaussians on the camera's axis at depths 2 and 10, broad enough to cover the image's centre
/// pixel almost fully (falloff above 0.99 there).
fn two_layers(front_opacity: f32, back_opacity: f32) -> Scene {
    Scene {
        means: vec![0.0, 0.0, 2.0, 0.0, 0.0, 10.0],
        quats: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
        scales: vec![0.5, 0.5, 0.5, 2.5, 2.5, 2.5],
        opacities: Opacities::Shared(vec![front_opacity, back_opacity]),
        colors: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        channels: 3,
    }
}

fn one_view() -> ViewBatch {
    let size = ImageSize::new(SIZE.0, SIZE.1).unwrap();
    ViewBatch::new(vec![view_at([0.0; 3], 0.0, size)], size).unwrap()
}

fn settings(depth: DepthStatistic) -> RasterSettings {
    RasterSettings { depth, ..RasterSettings::default() }
}

/// The depth at the pixel the optical axis passes through.
fn centre_depth(scene: &Scene, depth: DepthStatistic) -> f32 {
    let views = one_view();
    let view = &views.views()[0];
    let forward = rasterize(&scene.gaussians(), &views, &settings(depth)).unwrap();
    let (x, y) = (view.cx.floor() as usize, view.cy.floor() as usize);
    forward.images.depth[y * SIZE.0 as usize + x]
}

#[test]
fn the_median_depth_is_the_surface_that_first_makes_the_pixel_half_opaque() {
    // An opaque front layer: the transmittance falls to 0.4 at depth 2.
    let opaque_front = two_layers(0.6, 0.9);
    assert_eq!(centre_depth(&opaque_front, DepthStatistic::Median), 2.0, "the front surface is seen");
    let blend = centre_depth(&opaque_front, DepthStatistic::Expected);
    assert!((4.5..5.5).contains(&blend), "the expected depth blends the layers to about 5, got {blend}");
    // A faint front layer: the transmittance stays at 0.7 past it and falls below one half at depth 10.
    let faint_front = two_layers(0.3, 0.9);
    assert_eq!(centre_depth(&faint_front, DepthStatistic::Median), 10.0, "the back surface is seen");
    // A pixel that never gets half opaque reports its expected depth.
    let faint = two_layers(0.2, 0.2);
    let (median, expected) =
        (centre_depth(&faint, DepthStatistic::Median), centre_depth(&faint, DepthStatistic::Expected));
    assert_eq!(median, expected, "below half opacity the median falls back to the expected depth");
}

/// `weights` with the depth's weights zero.
fn without_depth(weights: &LossWeights) -> LossWeights {
    LossWeights { colors: weights.colors.clone(), alpha: weights.alpha.clone(), depth: vec![0.0; weights.depth.len()] }
}

#[test]
fn a_median_depth_render_changes_nothing_but_the_depth() {
    let mut rng = Rng::new(21);
    let scene = Scene::random(&mut rng, 40, 3, (0.1, 0.4));
    let views = one_view();
    let weights = LossWeights::random(&mut rng, 1, views.size(), 3);
    let expected_settings = settings(DepthStatistic::Expected);
    let (expected, expected_grads) = render_with_grads(&scene, &views, &expected_settings, &without_depth(&weights));
    let (median, median_grads) = render_with_grads(&scene, &views, &settings(DepthStatistic::Median), &weights);
    assert_eq!(median.images.colors, expected.images.colors, "colours do not depend on the depth statistic");
    assert_eq!(median.images.alpha, expected.images.alpha, "alpha does not depend on the depth statistic");
    assert_eq!(median_grads, expected_grads, "a median render's gradients are those of its colours and alpha");
    let differing = median.images.depth.iter().zip(&expected.images.depth).filter(|(m, e)| m != e).count();
    assert!(differing > 0, "some pixel of 40 overlapping Gaussians sees a surface other than the blend");
}

#[test]
fn the_host_refuses_a_depth_gradient_of_a_median_depth() {
    let scene = two_layers(0.6, 0.9);
    let views = one_view();
    let settings = settings(DepthStatistic::Median);
    let forward = rasterize(&scene.gaussians(), &views, &settings).unwrap();
    let depth = vec![1.0; views.size().area()];
    let grads = ImageGrads { depth: Some(&depth), ..ImageGrads::default() };
    let refused = rasterize_backward(&scene.gaussians(), &views, &settings, &forward, &grads);
    assert!(
        matches!(&refused, Err(SplatError::InvalidSettings { detail }) if detail.contains("median depth")),
        "a depth gradient of a median render is refused, got {refused:?}"
    );
}

/// Renders `scene` on `device` under autodiff with the loss of `weights` and returns the means' gradient.
fn means_gradient(device: &Device, scene: &Scene, depth: DepthStatistic, weights: &LossWeights) -> Vec<f32> {
    let views = one_view();
    let gaussians = gaussian_tensors(scene, 1, device, true);
    let settings = RenderSettings { raster: settings(depth), background: None };
    let images = render(&gaussians, &camera_tensors(&views, device), &settings).unwrap();
    let grads = weighted_loss(&images, weights, device).backward();
    values(gaussians.means.grad(&grads).expect("means gradient"))
}

#[test]
fn the_tensor_op_detaches_a_median_depth() {
    let device = Device::flex().autodiff();
    let scene = Scene::random(&mut Rng::new(8), 30, 3, (0.1, 0.4));
    let size = one_view().size();
    let weights = LossWeights::random(&mut Rng::new(9), 1, size, 3);
    let median = means_gradient(&device, &scene, DepthStatistic::Median, &weights);
    let expected = means_gradient(&device, &scene, DepthStatistic::Expected, &without_depth(&weights));
    assert_eq!(median, expected, "a median depth in the loss adds no gradient");
    let with_depth = means_gradient(&device, &scene, DepthStatistic::Expected, &weights);
    assert_ne!(with_depth, expected, "an expected depth in the loss does add one");
}

#[cfg(feature = "wgpu")]
#[test]
fn wgpu_renders_the_median_depth_as_the_host_does() {
    use crate::cube::{assert_close_to_host_with, cube_device, render_on_with};

    let device = cube_device().autodiff();
    let mut rng = Rng::new(33);
    let size = ImageSize::new(37, 29).unwrap();
    let views = ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([0.4, 0.1, -0.5], 0.2, size)], size).unwrap();
    let scene = Scene::random(&mut rng, 60, 3, (0.1, 0.4));
    let weights = LossWeights::random(&mut rng, 2, size, 3);
    let raster = settings(DepthStatistic::Median);
    let result = render_on_with(&device, &scene, &views, None, &weights, &raster);
    assert_close_to_host_with("median depth", &result, &scene, &views, None, &weights, &raster);
}
