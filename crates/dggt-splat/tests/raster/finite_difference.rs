//! The hand-written backward against central finite differences of the forward, on a smooth scene: a few
//! large Gaussians seen by two cameras, every footprint reaching every pixel with alpha well inside
//! `[1/255, 0.999]`, transmittance far above 1e-4 and every centre inside the field of view, so no discrete
//! decision changes within a step.

use dggt_geom::ImageSize;
use dggt_splat::{Opacities, RasterSettings, Rasterized, ViewBatch, rasterize};

use crate::scenes::{LossWeights, Rng, Scene, render_with_grads, view_at};

fn smooth_scene() -> (Scene, ViewBatch, RasterSettings) {
    let mut rng = Rng::new(7);
    let size = ImageSize::new(24, 20).unwrap();
    let views =
        ViewBatch::new(vec![view_at([0.0, 0.0, 0.0], 0.0, size), view_at([0.3, -0.1, 0.2], 0.08, size)], size).unwrap();
    let count = 4;
    let mut scene = Scene::random(&mut rng, count, 4, (1.6, 2.4));
    for i in 0..count {
        scene.means[3 * i] *= 0.3;
        scene.means[3 * i + 1] *= 0.3;
        scene.means[3 * i + 2] = 4.0 + 0.5 * i as f32;
    }
    scene.opacities = Opacities::Shared(rng.ranges(count, 0.3, 0.6));
    let settings = RasterSettings { background: Some(vec![0.2, -0.1, 0.5, 0.3]), ..RasterSettings::default() };
    (scene, views, settings)
}

/// Asserts the conditions that make the loss smooth around the scene.
fn assert_smooth(forward: &Rasterized, scene: &Scene, size: ImageSize) {
    let count = scene.len();
    let Opacities::Shared(opacities) = &scene.opacities else { unreachable!() };
    for (v, stats) in forward.stats.iter().enumerate() {
        assert_eq!(stats.kept, count, "view {v}: {stats}");
    }
    for k in 0..forward.projection.culled.len() {
        let [mx, my] = [forward.projection.means2d[2 * k], forward.projection.means2d[2 * k + 1]];
        assert!(mx > 0.0 && mx < size.width as f32 && my > 0.0 && my < size.height as f32, "centre {k} outside");
        let [a, b, c] = [0, 1, 2].map(|j| forward.projection.conics[3 * k + j]);
        for y in 0..size.height {
            for x in 0..size.width {
                let (dx, dy) = (mx - x as f32 - 0.5, my - y as f32 - 0.5);
                let alpha = opacities[k % count] * (-(0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy)).exp();
                assert!(alpha > 1.5 / 255.0 && alpha < 0.9, "footprint {k} at ({x}, {y}): alpha {alpha}");
            }
        }
    }
    assert!(forward.transmittance.iter().all(|t| *t > 1e-2), "no pixel near the early stop");
}

/// Selects one input buffer of the scene or the settings.
type Select = for<'a> fn(&'a mut Scene, &'a mut RasterSettings) -> &'a mut Vec<f32>;

/// Central differences of `loss` along every value of the selected buffer, dividing by the step actually
/// representable in f32.
fn numeric_gradient(
    scene: &mut Scene,
    settings: &mut RasterSettings,
    select: Select,
    step: f32,
    loss: &dyn Fn(&Scene, &RasterSettings) -> f64,
) -> Vec<f64> {
    let len = select(scene, settings).len();
    (0..len)
        .map(|k| {
            let original = select(scene, settings)[k];
            let mut evaluate = |delta: f32| {
                select(scene, settings)[k] = original + delta;
                let actual = select(scene, settings)[k] as f64 - original as f64;
                (loss(scene, settings), actual)
            };
            let (plus, h_plus) = evaluate(step);
            let (minus, h_minus) = evaluate(-step);
            select(scene, settings)[k] = original;
            (plus - minus) / (h_plus - h_minus)
        })
        .collect()
}

/// Compares one tensor's analytic gradient with finite differences: `|fd - g| <= rtol · max|g| + atol`.
fn check(name: &str, analytic: &[f32], numeric: &[f64], rtol: f64, atol: f64) {
    let scale = analytic.iter().fold(0.0f64, |m, g| m.max(g.abs() as f64));
    let error = analytic.iter().zip(numeric).fold(0.0f64, |m, (a, n)| m.max((*a as f64 - n).abs()));
    eprintln!(
        "finite differences {name:<11} max |grad| {scale:.3e}  max abs err {error:.2e}  rel {:.2e}",
        error / scale
    );
    assert!(scale > 1e-3, "{name}: gradient vanishes, the check would be empty");
    for (k, (a, n)) in analytic.iter().zip(numeric).enumerate() {
        assert!((*a as f64 - n).abs() <= rtol * scale + atol, "{name}[{k}]: analytic {a}, finite difference {n}");
    }
}

#[test]
fn backward_matches_central_differences() {
    let (mut scene, views, mut settings) = smooth_scene();
    let size = views.size();
    let weights = LossWeights::random(&mut Rng::new(11), views.len(), size, scene.channels);
    let (forward, grads) = render_with_grads(&scene, &views, &settings, &weights);
    assert_smooth(&forward, &scene, size);

    let loss = |scene: &Scene, settings: &RasterSettings| {
        weights.loss(&rasterize(&scene.gaussians(), &views, settings).unwrap())
    };
    let step = 1e-2;
    let mut numeric = |select: Select| numeric_gradient(&mut scene, &mut settings, select, step, &loss);
    let means = numeric(|s, _| &mut s.means);
    let quats = numeric(|s, _| &mut s.quats);
    let scales = numeric(|s, _| &mut s.scales);
    let colors = numeric(|s, _| &mut s.colors);
    let opacities = numeric(|s, _| match &mut s.opacities {
        Opacities::Shared(v) | Opacities::PerView(v) => v,
    });
    let background = numeric(|_, settings| settings.background.as_mut().unwrap());

    let (rtol, atol) = (1e-3, 1e-4);
    check("means", &grads.means, &means, rtol, atol);
    check("quats", &grads.quats, &quats, rtol, atol);
    check("scales", &grads.scales, &scales, rtol, atol);
    check("opacities", grads.opacities.values(), &opacities, rtol, atol);
    check("colors", &grads.colors, &colors, rtol, atol);
    check("background", &grads.background, &background, rtol, atol);
}
