//! The rasteriser alone at the release's scale: `G` Gaussians spread like pixel-aligned ones in front of `V`
//! cameras along a stretch of road, rendered forward, and forward then backward (the loss is the sum of the
//! colours; gradients for means, rotations, scales, opacities and colours).
//!
//! The scene (the one `scripts/reference_bench.py` renders with gsplat): each Gaussian sits at a uniform pixel
//! of the first view, at depth `2 + 58 r1 r2` m, back-projected with `fx = fy = 300 W / 518`, the principal point at
//! the image centre; rotation `(1, 0.2r, 0.2r, 0.2r)` (w x y z, normalised by the rasteriser); scales
//! `(s, s (0.5 + r), 0.3 s)` with `s = (0.5 + 1.5r) depth / fx` (one to four pixels wide); opacity
//! `0.3 + 0.65r`; RGB uniform. View `i` of `V` has the identity rotation and sits `1.5 i / V` m further along
//! the optical axis (world-to-camera translation `(0, 0, -1.5 i / V)`). `r` are SplitMix64 draws in `[0, 1)`.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::random::SplitMix64;
use dggt_geom::ImageSize;
use dggt_splat::{CameraTensors, GaussianTensors, OpacityTensor, RenderSettings, render};

use super::{ComputeOptions, Passes, Record, ScaleSpec, timed};
use crate::error::BenchError;
use crate::stages::settle;

/// `raster/{G}x{V}/forward` and `raster/{G}x{V}/forward+backward`.
pub fn raster_records(options: &ComputeOptions, spec: &ScaleSpec, device: &Device, keep: &mut impl FnMut(Record)) {
    let scene = RoadScene::new(spec.raster_gaussians, spec.raster_views, spec.image, options.seed);
    for passes in [Passes::Forward, Passes::ForwardBackward] {
        let key = format!("raster/{}x{}/{}", spec.raster_gaussians, spec.raster_views, passes.name());
        let device = match passes {
            Passes::Forward => device.clone(),
            Passes::ForwardBackward => device.clone().autodiff(),
        };
        let gaussians = scene.gaussians(&device, passes == Passes::ForwardBackward);
        let cameras = scene.cameras(&device);
        let record = timed(key, options, &device, || render_once(&gaussians, &cameras, passes));
        keep(record.with_note(format!("{}x{} views, RGB, default settings", spec.image.width, spec.image.height)));
    }
}

fn render_once(gaussians: &GaussianTensors, cameras: &CameraTensors, passes: Passes) -> Result<(), BenchError> {
    let images = render(gaussians, cameras, &RenderSettings::default())?;
    let loss = images.colors.sum();
    match passes {
        Passes::Forward => settle(&loss),
        Passes::ForwardBackward => {
            let grads = loss.backward();
            let grad = |t: &Tensor<2>| {
                t.grad(&grads).map(|g| g.sum()).ok_or_else(|| BenchError::Missing("raster: a gradient is missing"))
            };
            let opacity = match &gaussians.opacities {
                OpacityTensor::Shared(values) => values.grad(&grads).map(|g| g.sum()),
                OpacityTensor::PerView(values) => values.grad(&grads).map(|g| g.sum()),
            }
            .ok_or_else(|| BenchError::Missing("raster: the opacity gradient is missing"))?;
            let total = grad(&gaussians.means)?
                + grad(&gaussians.quats_wxyz)?
                + grad(&gaussians.scales)?
                + grad(&gaussians.colors)?
                + opacity;
            settle(&total)
        }
    }
}

/// The benchmark scene on the host, structure of arrays.
struct RoadScene {
    count: usize,
    size: ImageSize,
    /// `fx = fy`, pixels.
    focal: f32,
    /// `(cx, cy)`, pixels: the image centre.
    principal_point: (f32, f32),
    means: Vec<f32>,
    quats: Vec<f32>,
    scales: Vec<f32>,
    opacities: Vec<f32>,
    colors: Vec<f32>,
    views: usize,
}

impl RoadScene {
    fn new(count: usize, views: usize, size: ImageSize, seed: u64) -> Self {
        let mut random = SplitMix64::new(seed);
        let focal = 300.0 * size.width as f32 / 518.0;
        let (cx, cy) = (size.width as f32 / 2.0, size.height as f32 / 2.0);
        let mut scene = Self {
            count,
            size,
            focal,
            principal_point: (cx, cy),
            means: Vec::with_capacity(3 * count),
            quats: Vec::with_capacity(4 * count),
            scales: Vec::with_capacity(3 * count),
            opacities: Vec::with_capacity(count),
            colors: Vec::with_capacity(3 * count),
            views,
        };
        for _ in 0..count {
            let (u, v) = (random.unit() * size.width as f32, random.unit() * size.height as f32);
            let depth = 2.0 + 58.0 * random.unit() * random.unit();
            scene.means.extend([(u - cx) * depth / focal, (v - cy) * depth / focal, depth]);
            scene.quats.extend([1.0, 0.2 * random.unit(), 0.2 * random.unit(), 0.2 * random.unit()]);
            let s = (0.5 + 1.5 * random.unit()) * depth / focal;
            scene.scales.extend([s, s * (0.5 + random.unit()), 0.3 * s]);
            scene.opacities.push(0.3 + 0.65 * random.unit());
            scene.colors.extend([random.unit(), random.unit(), random.unit()]);
        }
        scene
    }

    fn gaussians(&self, device: &Device, trainable: bool) -> GaussianTensors {
        let tensor = |values: &[f32], width: usize| {
            let t = Tensor::<2>::from_data(TensorData::new(values.to_vec(), [self.count, width]), device);
            if trainable { t.require_grad() } else { t }
        };
        let opacities = Tensor::<1>::from_data(TensorData::new(self.opacities.clone(), [self.count]), device);
        GaussianTensors {
            means: tensor(&self.means, 3),
            quats_wxyz: tensor(&self.quats, 4),
            scales: tensor(&self.scales, 3),
            opacities: OpacityTensor::Shared(if trainable { opacities.require_grad() } else { opacities }),
            colors: tensor(&self.colors, 3),
        }
    }

    fn cameras(&self, device: &Device) -> CameraTensors {
        let (cx, cy) = self.principal_point;
        let mut world_to_camera = Vec::with_capacity(16 * self.views);
        let mut intrinsics = Vec::with_capacity(9 * self.views);
        for i in 0..self.views {
            let z = -1.5 * i as f32 / self.views as f32;
            world_to_camera.extend([1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, z, 0.0, 0.0, 0.0, 1.0]);
            intrinsics.extend([self.focal, 0.0, cx, 0.0, self.focal, cy, 0.0, 0.0, 1.0]);
        }
        CameraTensors {
            world_to_camera: Tensor::from_data(TensorData::new(world_to_camera, [self.views, 4, 4]), device),
            intrinsics: Tensor::from_data(TensorData::new(intrinsics, [self.views, 3, 3]), device),
            size: self.size,
        }
    }
}
