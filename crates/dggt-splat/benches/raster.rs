//! Host rasteriser throughput at DGGT's scale: pixel-aligned Gaussians (one per input pixel, 1-3 pixels wide,
//! depths 2-60 m) rendered at 518x350 into 1 or 12 views, forward and forward + backward.
//!
//! `cargo bench -p dggt-splat --bench raster` runs N in {10k, 100k, 1M}; set `DGGT_BENCH_GAUSSIANS` (comma
//! separated, e.g. `10000,100000,1000000,2200000`) and `DGGT_BENCH_VIEWS` (e.g. `1,12`) to choose.
//!
//! With the `wgpu` feature the same scenes are also rendered by the CubeCL kernels on burn's default wgpu
//! device, through the tensor API with autodiff (`--features wgpu`; `DGGT_BENCH_DEVICES=host`, `wgpu` or
//! `host,wgpu` chooses). Each GPU measurement follows one untimed warm-up call (kernel compilation) and ends
//! by reading one value back, so it covers the whole call.

use std::time::Instant;

use dggt_data::random::SplitMix64;
use dggt_geom::{ImageSize, PinholeIntrinsics};
use dggt_splat::{
    Gaussians, ImageGrads, Opacities, PinholeView, RasterSettings, ViewBatch, rasterize, rasterize_backward,
};

struct Scene {
    means: Vec<f32>,
    quats: Vec<f32>,
    scales: Vec<f32>,
    opacities: Vec<f32>,
    colors: Vec<f32>,
}

fn scene(count: usize, size: ImageSize, k: &PinholeIntrinsics) -> Scene {
    let mut random = SplitMix64::new(count as u64);
    let mut s = Scene { means: vec![], quats: vec![], scales: vec![], opacities: vec![], colors: vec![] };
    for _ in 0..count {
        let (u, v) = (random.unit() * size.width as f32, random.unit() * size.height as f32);
        let depth = 2.0 + 58.0 * random.unit() * random.unit();
        s.means.extend([(u - k.cx as f32) * depth / k.fx as f32, (v - k.cy as f32) * depth / k.fy as f32, depth]);
        s.quats.extend([1.0, 0.2 * random.unit(), 0.2 * random.unit(), 0.2 * random.unit()]);
        let pixels = 0.5 + 1.5 * random.unit();
        let scale = pixels * depth / k.fx as f32;
        s.scales.extend([scale, scale * (0.5 + random.unit()), scale * 0.3]);
        s.opacities.push(0.3 + 0.65 * random.unit());
        s.colors.extend([random.unit(), random.unit(), random.unit()]);
    }
    s
}

fn views(count: usize, size: ImageSize, k: &PinholeIntrinsics) -> ViewBatch {
    // Cameras along a 1.5 m stretch of road, as the frames of a DGGT sample.
    let views = (0..count)
        .map(|i| {
            let z = -(i as f32) * 1.5 / count.max(1) as f32;
            PinholeView {
                world_to_camera: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, z]],
                fx: k.fx as f32,
                fy: k.fy as f32,
                cx: k.cx as f32,
                cy: k.cy as f32,
            }
        })
        .collect();
    ViewBatch::new(views, size).expect("valid views")
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).map(|l| l.to_owned()))
        .and_then(|l| l.split_whitespace().nth(1).and_then(|kb| kb.parse::<f64>().ok()))
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn list(var: &str, default: &[usize]) -> Vec<usize> {
    std::env::var(var)
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

fn main() {
    let devices = std::env::var("DGGT_BENCH_DEVICES").unwrap_or_else(|_| "host,wgpu".into());
    if devices.split(',').any(|d| d.trim() == "host") {
        host();
    }
    #[cfg(feature = "wgpu")]
    if devices.split(',').any(|d| d.trim() == "wgpu") {
        gpu::wgpu();
    }
}

fn host() {
    let size = ImageSize::new(518, 350).expect("size");
    let k = PinholeIntrinsics::new(300.0, 300.0, 259.0, 175.0).expect("intrinsics");
    let settings = RasterSettings::default();
    println!("host, threads: {}", rayon::current_num_threads());
    println!(
        "{:>9} {:>5} {:>12} {:>12} {:>10} {:>14}",
        "gaussians", "views", "forward ms", "fwd+bwd ms", "kept/view", "peak RSS MiB"
    );
    for count in list("DGGT_BENCH_GAUSSIANS", &[10_000, 100_000, 1_000_000]) {
        let s = scene(count, size, &k);
        let gaussians = Gaussians::new(&s.means, &s.quats, &s.scales, Opacities::Shared(&s.opacities), &s.colors, 3)
            .expect("scene");
        for view_count in list("DGGT_BENCH_VIEWS", &[1, 12]) {
            let batch = views(view_count, size, &k);
            let started = Instant::now();
            let forward = rasterize(&gaussians, &batch, &settings).expect("forward");
            let forward_ms = started.elapsed().as_secs_f64() * 1e3;
            let ones = vec![1.0f32; forward.images.colors.len()];
            let grads = ImageGrads { colors: Some(&ones), alpha: None, depth: None };
            rasterize_backward(&gaussians, &batch, &settings, &forward, &grads).expect("backward");
            let total_ms = started.elapsed().as_secs_f64() * 1e3;
            let kept = forward.stats.iter().map(|s| s.kept).sum::<usize>() / view_count;
            println!(
                "{count:>9} {view_count:>5} {forward_ms:>12.1} {total_ms:>12.1} {kept:>10} {:>14.0}",
                peak_rss_mib()
            );
        }
    }
}

#[cfg(feature = "wgpu")]
mod gpu {
    use std::time::Instant;

    use burn::tensor::{Device, DeviceKind, Tensor, TensorData};
    use dggt_geom::{ImageSize, PinholeIntrinsics};
    use dggt_splat::{CameraTensors, GaussianTensors, OpacityTensor, RenderSettings, ViewBatch, render_with_stats};

    use super::{list, scene, views};

    fn tensor<const D: usize>(values: &[f32], shape: [usize; D], device: &Device) -> Tensor<D> {
        Tensor::from_data(TensorData::new(values.to_vec(), shape), device)
    }

    fn cameras(batch: &ViewBatch, device: &Device) -> CameraTensors {
        let mut viewmats = Vec::new();
        let mut intrinsics = Vec::new();
        for view in batch.views() {
            viewmats.extend(view.world_to_camera.iter().flatten());
            viewmats.extend([0.0, 0.0, 0.0, 1.0]);
            intrinsics.extend([view.fx, 0.0, view.cx, 0.0, view.fy, view.cy, 0.0, 0.0, 1.0]);
        }
        CameraTensors {
            world_to_camera: tensor(&viewmats, [batch.len(), 4, 4], device),
            intrinsics: tensor(&intrinsics, [batch.len(), 3, 3], device),
            size: batch.size(),
        }
    }

    /// One forward (and, with `backward`, backward) call; returns the milliseconds and the kept count per view.
    fn call(gaussians: &GaussianTensors, cameras: &CameraTensors, backward: bool) -> (f64, usize) {
        let started = Instant::now();
        let (images, stats) = render_with_stats(gaussians, cameras, &RenderSettings::default()).expect("render");
        let loss = images.colors.sum();
        let value = if backward {
            let grads = loss.backward();
            let grad = gaussians.means.grad(&grads).expect("means gradient");
            grad.sum().into_scalar::<f32>()
        } else {
            loss.into_scalar::<f32>()
        };
        std::hint::black_box(value);
        let kept = stats.iter().map(|s| s.kept).sum::<usize>() / stats.len().max(1);
        (started.elapsed().as_secs_f64() * 1e3, kept)
    }

    pub fn wgpu() {
        let size = ImageSize::new(518, 350).expect("size");
        let k = PinholeIntrinsics::new(300.0, 300.0, 259.0, 175.0).expect("intrinsics");
        let device = Device::wgpu(DeviceKind::DefaultDevice).autodiff();
        println!("wgpu (CubeCL kernels), default adapter");
        println!("{:>9} {:>5} {:>12} {:>12} {:>10}", "gaussians", "views", "forward ms", "fwd+bwd ms", "kept/view");
        for count in list("DGGT_BENCH_GAUSSIANS", &[10_000, 100_000, 1_000_000]) {
            let s = scene(count, size, &k);
            let gaussians = GaussianTensors {
                means: tensor(&s.means, [count, 3], &device).require_grad(),
                quats_wxyz: tensor(&s.quats, [count, 4], &device).require_grad(),
                scales: tensor(&s.scales, [count, 3], &device).require_grad(),
                opacities: OpacityTensor::Shared(tensor(&s.opacities, [count], &device).require_grad()),
                colors: tensor(&s.colors, [count, 3], &device).require_grad(),
            };
            for view_count in list("DGGT_BENCH_VIEWS", &[1, 12]) {
                let cameras = cameras(&views(view_count, size, &k), &device);
                call(&gaussians, &cameras, true);
                let (forward_ms, kept) = call(&gaussians, &cameras, false);
                let (total_ms, _) = call(&gaussians, &cameras, true);
                println!("{count:>9} {view_count:>5} {forward_ms:>12.1} {total_ms:>12.1} {kept:>10}");
            }
        }
    }
}
