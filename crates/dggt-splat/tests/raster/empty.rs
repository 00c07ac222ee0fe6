//! Scenes with nothing to draw: no Gaussians, a view that culls all of them, no views.

use dggt_geom::ImageSize;
use dggt_splat::{Gaussians, ImageGrads, Opacities, RasterSettings, ViewBatch, rasterize, rasterize_backward};

use crate::scenes::{LossWeights, Rng, Scene, render_with_grads, view_at};

#[test]
fn no_gaussians_render_the_background() {
    let size = ImageSize::new(19, 13).unwrap();
    let views = ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([1.0, 0.0, 0.0], 0.3, size)], size).unwrap();
    let background = vec![0.1, 0.2, 0.3];
    let settings = RasterSettings { background: Some(background.clone()), ..RasterSettings::default() };
    let gaussians = Gaussians::new(&[], &[], &[], Opacities::Shared(&[]), &[], 3).unwrap();
    let forward = rasterize(&gaussians, &views, &settings).unwrap();
    let pixels = 2 * size.area();
    assert_eq!(forward.images.colors, background.repeat(pixels));
    assert_eq!(forward.images.alpha, vec![0.0; pixels]);
    assert_eq!(forward.images.depth, vec![0.0; pixels]);
    assert!(forward.stats.iter().all(|s| s.gaussians == 0 && s.tile_intersections == 0));

    let weights = LossWeights::random(&mut Rng::new(1), 2, size, 3);
    let grads = rasterize_backward(&gaussians, &views, &settings, &forward, &weights.image_grads()).unwrap();
    assert!(grads.means.is_empty() && grads.colors.is_empty() && grads.opacities.values().is_empty());
    for k in 0..3 {
        let expected: f64 = weights.colors.iter().skip(k).step_by(3).map(|g| *g as f64).sum();
        assert!((grads.background[k] as f64 - expected).abs() < 1e-4, "background {k}");
    }
}

#[test]
fn a_view_that_culls_everything_renders_the_background_and_adds_no_gradient() {
    let mut rng = Rng::new(9);
    let size = ImageSize::new(24, 20).unwrap();
    let front = view_at([0.0; 3], 0.0, size);
    // Looking backwards: every Gaussian is behind this camera.
    let back = view_at([0.0; 3], std::f32::consts::PI, size);
    let views = ViewBatch::new(vec![front, back], size).unwrap();
    let scene = Scene::random(&mut rng, 30, 3, (0.05, 0.3));
    let background = vec![0.5, 0.25, 1.0];
    let settings = RasterSettings { background: Some(background.clone()), ..RasterSettings::default() };
    let weights = LossWeights::random(&mut rng, 2, size, 3);
    let (forward, grads) = render_with_grads(&scene, &views, &settings, &weights);
    let pixels = size.area();
    assert_eq!(forward.stats[1].kept, 0);
    assert_eq!(forward.stats[1].near_plane, 30);
    assert_eq!(forward.images.colors[3 * pixels..], background.repeat(pixels)[..]);
    assert!(forward.images.alpha[pixels..].iter().all(|a| *a == 0.0));
    assert!(forward.stats[0].kept > 0);

    // The Gaussians' gradients equal those of rendering the front view alone.
    let front_only = ViewBatch::new(vec![front], size).unwrap();
    let front_weights = LossWeights {
        colors: weights.colors[..3 * pixels].to_vec(),
        alpha: weights.alpha[..pixels].to_vec(),
        depth: weights.depth[..pixels].to_vec(),
    };
    let (_, front_grads) = render_with_grads(&scene, &front_only, &settings, &front_weights);
    assert_eq!(grads.means, front_grads.means);
    assert_eq!(grads.quats, front_grads.quats);
    assert_eq!(grads.opacities, front_grads.opacities);
}

#[test]
fn no_views_render_nothing() {
    let size = ImageSize::new(8, 8).unwrap();
    let views = ViewBatch::new(vec![], size).unwrap();
    let scene = Scene::random(&mut Rng::new(2), 5, 3, (0.1, 0.2));
    let gaussians = scene.gaussians();
    let settings = RasterSettings::default();
    let forward = rasterize(&gaussians, &views, &settings).unwrap();
    assert!(forward.images.colors.is_empty() && forward.stats.is_empty());
    let grads = rasterize_backward(&gaussians, &views, &settings, &forward, &ImageGrads::default()).unwrap();
    assert_eq!(grads.means, vec![0.0; 15]);
}
