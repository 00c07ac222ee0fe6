//! Owned test scenes, a small deterministic random source, and the weighted loss the tests differentiate.

use dggt_geom::ImageSize;
use dggt_splat::{
    DepthStatistic, GaussianGrads, Gaussians, ImageGrads, Opacities, PinholeView, RasterSettings, Rasterized,
    ViewBatch, rasterize, rasterize_backward,
};

/// The seeded generator of the test scenes.
pub use dggt_data::random::SplitMix64 as Rng;

/// Gaussians as owned buffers (see [`Gaussians`] for the shapes).
#[derive(Debug, Clone)]
pub struct Scene {
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub scales: Vec<f32>,
    pub opacities: Opacities<Vec<f32>>,
    pub colors: Vec<f32>,
    pub channels: usize,
}

impl Scene {
    pub fn gaussians(&self) -> Gaussians<'_> {
        Gaussians::new(&self.means, &self.quats, &self.scales, self.opacities.as_slices(), &self.colors, self.channels)
            .unwrap()
    }

    pub fn len(&self) -> usize {
        self.means.len() / 3
    }

    /// `count` Gaussians spread in front of the origin looking down +z.
    pub fn random(rng: &mut Rng, count: usize, channels: usize, scale: (f32, f32)) -> Self {
        let mut means = Vec::with_capacity(3 * count);
        for _ in 0..count {
            means.extend([rng.range(-1.2, 1.2), rng.range(-0.9, 0.9), rng.range(2.5, 6.0)]);
        }
        Self {
            means,
            quats: rng.ranges(4 * count, -1.0, 1.0),
            scales: rng.ranges(3 * count, scale.0, scale.1),
            opacities: Opacities::Shared(rng.ranges(count, 0.05, 0.95)),
            colors: rng.ranges(channels * count, -0.2, 1.2),
            channels,
        }
    }
}

/// A camera at `position` (world) looking along +z after a rotation of `yaw` about y, OpenCV axes.
pub fn view_at(position: [f32; 3], yaw: f32, size: ImageSize) -> PinholeView {
    let (s, c) = yaw.sin_cos();
    // Camera-from-world rotation R = Ry(yaw)ᵀ; t = -R position.
    let r = [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]];
    let t: Vec<f32> =
        r.iter().map(|row| -(row[0] * position[0] + row[1] * position[1] + row[2] * position[2])).collect();
    let (w, h) = (size.width as f32, size.height as f32);
    PinholeView {
        world_to_camera: std::array::from_fn(|i| [r[i][0], r[i][1], r[i][2], t[i]]),
        fx: 0.9 * w,
        fy: 0.9 * w,
        cx: 0.5 * w + 0.3,
        cy: 0.5 * h - 0.2,
    }
}

/// Fixed random weights defining `L = Σ colors·wc + Σ alpha·wa + Σ depth·wd`.
pub struct LossWeights {
    pub colors: Vec<f32>,
    pub alpha: Vec<f32>,
    pub depth: Vec<f32>,
}

impl LossWeights {
    pub fn random(rng: &mut Rng, views: usize, size: ImageSize, channels: usize) -> Self {
        let pixels = views * size.area();
        Self {
            colors: rng.ranges(pixels * channels, -1.0, 1.0),
            alpha: rng.ranges(pixels, -1.0, 1.0),
            depth: rng.ranges(pixels, -0.3, 0.3),
        }
    }

    pub fn image_grads(&self) -> ImageGrads<'_> {
        ImageGrads { colors: Some(&self.colors), alpha: Some(&self.alpha), depth: Some(&self.depth) }
    }

    /// The gradients a render with `depth` takes: a median depth takes none (it is a constant of the render).
    pub fn image_grads_for(&self, depth: DepthStatistic) -> ImageGrads<'_> {
        match depth {
            DepthStatistic::Expected => self.image_grads(),
            DepthStatistic::Median => ImageGrads { depth: None, ..self.image_grads() },
        }
    }

    pub fn loss(&self, r: &Rasterized) -> f64 {
        let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum::<f64>();
        dot(&r.images.colors, &self.colors) + dot(&r.images.alpha, &self.alpha) + dot(&r.images.depth, &self.depth)
    }
}

/// Forward and backward of `scene`.
pub fn render_with_grads(
    scene: &Scene,
    views: &ViewBatch,
    settings: &RasterSettings,
    weights: &LossWeights,
) -> (Rasterized, GaussianGrads) {
    let gaussians = scene.gaussians();
    let forward = rasterize(&gaussians, views, settings).unwrap();
    let grads =
        rasterize_backward(&gaussians, views, settings, &forward, &weights.image_grads_for(settings.depth)).unwrap();
    (forward, grads)
}
