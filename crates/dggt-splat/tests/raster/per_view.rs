//! Per-view opacities: rendering V views in one call equals rendering each view on its own with that view's
//! opacities shared, for the images and for every gradient.

use dggt_geom::ImageSize;
use dggt_splat::{Opacities, RasterSettings, ViewBatch};

use crate::scenes::{LossWeights, Rng, Scene, render_with_grads, view_at};

/// `|a - b| <= 1e-6 · max|b| + 1e-9` elementwise (the batch sums views in f64 before rounding once).
fn assert_close(name: &str, batch: &[f32], summed: &[f64]) {
    assert_eq!(batch.len(), summed.len(), "{name}");
    let scale = summed.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (k, (b, s)) in batch.iter().zip(summed).enumerate() {
        assert!((*b as f64 - s).abs() <= 1e-6 * scale + 1e-9, "{name}[{k}]: batch {b}, sum of views {s}");
    }
}

fn slice_weights(weights: &LossWeights, view: usize, pixels: usize, channels: usize) -> LossWeights {
    LossWeights {
        colors: weights.colors[view * pixels * channels..(view + 1) * pixels * channels].to_vec(),
        alpha: weights.alpha[view * pixels..(view + 1) * pixels].to_vec(),
        depth: weights.depth[view * pixels..(view + 1) * pixels].to_vec(),
    }
}

#[test]
fn batch_with_per_view_opacities_equals_separate_views() {
    let mut rng = Rng::new(3);
    let size = ImageSize::new(40, 32).unwrap();
    let cameras = vec![
        view_at([0.0, 0.0, 0.0], 0.0, size),
        view_at([0.4, 0.1, 0.3], 0.12, size),
        view_at([-0.5, -0.2, -0.4], -0.2, size),
    ];
    let views = ViewBatch::new(cameras.clone(), size).unwrap();
    let (count, channels) = (60, 4);
    let mut scene = Scene::random(&mut rng, count, channels, (0.05, 0.4));
    let mut per_view = rng.ranges(views.len() * count, 0.02, 0.95);
    // Some Gaussians fade out in some views only.
    for k in (0..per_view.len()).step_by(7) {
        per_view[k] = 0.001;
    }
    scene.opacities = Opacities::PerView(per_view.clone());
    let settings = RasterSettings { background: Some(vec![0.1, 0.2, 0.3, 0.4]), ..RasterSettings::default() };
    let weights = LossWeights::random(&mut rng, views.len(), size, channels);
    let (batch, batch_grads) = render_with_grads(&scene, &views, &settings, &weights);
    let Opacities::PerView(batch_opacity_grads) = &batch_grads.opacities else { panic!("per-view gradients expected") };
    assert!(batch.stats.iter().all(|s| s.transparent > 0 && s.kept > 0));

    let pixels = size.area();
    let mut summed_means = vec![0.0f64; 3 * count];
    let mut summed_quats = vec![0.0f64; 4 * count];
    let mut summed_scales = vec![0.0f64; 3 * count];
    let mut summed_colors = vec![0.0f64; channels * count];
    let mut summed_background = vec![0.0f64; channels];
    let add = |sum: &mut Vec<f64>, values: &[f32]| sum.iter_mut().zip(values).for_each(|(s, v)| *s += *v as f64);
    for (v, camera) in cameras.iter().enumerate() {
        let single_views = ViewBatch::new(vec![*camera], size).unwrap();
        let single_scene =
            Scene { opacities: Opacities::Shared(per_view[v * count..(v + 1) * count].to_vec()), ..scene.clone() };
        let single_weights = slice_weights(&weights, v, pixels, channels);
        let (single, grads) = render_with_grads(&single_scene, &single_views, &settings, &single_weights);

        // Images, projection and statistics are bit-identical.
        assert_eq!(single.images.colors, batch.images.colors[v * pixels * channels..(v + 1) * pixels * channels]);
        assert_eq!(single.images.alpha, batch.images.alpha[v * pixels..(v + 1) * pixels]);
        assert_eq!(single.images.depth, batch.images.depth[v * pixels..(v + 1) * pixels]);
        assert_eq!(single.projection.culled, batch.projection.culled[v * count..(v + 1) * count]);
        assert_eq!(single.stats[0], batch.stats[v]);
        // A view's opacity gradient comes from that view alone: bit-identical too.
        let Opacities::Shared(single_opacity_grads) = &grads.opacities else { panic!("shared gradients expected") };
        assert_eq!(single_opacity_grads[..], batch_opacity_grads[v * count..(v + 1) * count]);
        add(&mut summed_means, &grads.means);
        add(&mut summed_quats, &grads.quats);
        add(&mut summed_scales, &grads.scales);
        add(&mut summed_colors, &grads.colors);
        add(&mut summed_background, &grads.background);
    }
    assert_close("means", &batch_grads.means, &summed_means);
    assert_close("quats", &batch_grads.quats, &summed_quats);
    assert_close("scales", &batch_grads.scales, &summed_scales);
    assert_close("colors", &batch_grads.colors, &summed_colors);
    assert_close("background", &batch_grads.background, &summed_background);
}

#[test]
fn shared_opacities_get_the_sum_of_identical_per_view_gradients() {
    let mut rng = Rng::new(5);
    let size = ImageSize::new(33, 17).unwrap();
    let views =
        ViewBatch::new(vec![view_at([0.0; 3], 0.05, size), view_at([0.2, 0.0, -0.3], -0.1, size)], size).unwrap();
    let count = 40;
    let shared = Scene::random(&mut rng, count, 3, (0.05, 0.3));
    let Opacities::Shared(values) = &shared.opacities else { unreachable!() };
    let repeated =
        Scene { opacities: Opacities::PerView([values.as_slice(), values.as_slice()].concat()), ..shared.clone() };
    let settings = RasterSettings::default();
    let weights = LossWeights::random(&mut rng, views.len(), size, 3);
    let (shared_forward, shared_grads) = render_with_grads(&shared, &views, &settings, &weights);
    let (repeated_forward, repeated_grads) = render_with_grads(&repeated, &views, &settings, &weights);
    assert_eq!(shared_forward.images, repeated_forward.images);
    assert_eq!(shared_grads.means, repeated_grads.means);
    let per_view = repeated_grads.opacities.values();
    let summed: Vec<f64> = (0..count).map(|i| per_view[i] as f64 + per_view[count + i] as f64).collect();
    assert_close("opacities", shared_grads.opacities.values(), &summed);
}
