//! Scenes whose Gaussians are the synthetic generator's ground truth: every input pixel's Gaussian sits where
//! its ray meets the scene (depth along the camera's axis), coloured as the generator rendered the pixel,
//! opaque unless the ray meets the sky, dynamic where the surface moves, never fading. Edits of such a scene
//! can be compared with the generator's own edited renders without a network in between.

#![allow(dead_code)]

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::glam::DVec3;
use dggt_geom::{PixelConvention, PosedCamera};
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_scene::{
    AssemblySettings, DynamicMotion, InputView, InstanceSettings, MeansGradient, PixelGaussians, Scene4d, TargetView,
};
use dggt_synth::{SynthConfig, SynthScene};

/// The generator's scene at `seed`: `frames` frames of the front camera at 96x64.
pub fn synth(seed: u64, frames: usize) -> SynthScene {
    synth_sized(seed, frames, 96, 64)
}

/// The generator's scene at `seed`: `frames` frames of the front camera at `width` x `height`.
pub fn synth_sized(seed: u64, frames: usize, width: u32, height: u32) -> SynthScene {
    dggt_synth::generate(&SynthConfig { seed, frames, cameras: 1, width, height }).unwrap()
}

/// The inverse of the Gaussian head's scale activation (`0.1 · softplus`).
fn scale_raw(scale: f64) -> f32 {
    let x = 10.0 * scale;
    (if x > 20.0 { x } else { x.exp_m1().ln() }) as f32
}

fn logit(p: f64) -> f32 {
    let p = p.clamp(0.02, 0.98);
    (p / (1.0 - p)).ln() as f32
}

/// The view of the front camera at `frame`.
pub fn view(synth: &SynthScene, frame: usize) -> InputView {
    InputView {
        rig_camera: 0,
        time: SynthConfig::frame_time(frame),
        camera: PosedCamera {
            world_from_camera: synth.world_from_camera(frame, 0).unwrap(),
            intrinsics: synth.intrinsics(),
        },
    }
}

/// The target of the front camera at `frame`.
pub fn target(synth: &SynthScene, frame: usize) -> TargetView {
    let view = view(synth, frame);
    TargetView { rig_camera: 0, time: view.time, camera: view.camera }
}

/// The ground-truth scene of `frames` (front camera), its moving objects found, rendered with instance motion.
pub fn oracle(synth: &SynthScene, frames: &[usize], device: &Device) -> Scene4d {
    let size = synth.image_size();
    let (width, height) = (size.width as usize, size.height as usize);
    let k = synth.intrinsics();
    let (mut raw, mut depth, mut dynamic) = (Vec::new(), Vec::new(), Vec::new());
    for &frame in frames {
        let pose = synth.world_from_camera(frame, 0).unwrap();
        let at = synth.at(SynthConfig::frame_time(frame)).unwrap();
        let image = synth.render_view(frame, 0).unwrap().image;
        for row in 0..height {
            for column in 0..width {
                let pixel = PixelConvention::Centred.coordinates(column as u32, row as u32);
                let along = DVec3::new((pixel.x - k.cx) / k.fx, (pixel.y - k.cy) / k.fy, 1.0);
                let hit = at.cast(pose.translation(), pose.transform_vector(along));
                let z = hit.map_or(100.0, |hit| pose.inverse().transform_point(hit.point).z);
                let rgb = image.get_pixel(column as u32, row as u32).0.map(|c| logit(c as f64 / 255.0));
                let opacity = if hit.is_some() { 6.0 } else { -12.0 };
                let scale = scale_raw(0.7 * z / k.fx);
                raw.extend(rgb);
                raw.extend([opacity, scale, scale, scale, 1.0, 0.0, 0.0, 0.0, 0.0]);
                depth.push(z as f32);
                dynamic.push(if hit.is_some_and(|hit| hit.dynamic) { 8.0f32 } else { -8.0 });
            }
        }
    }
    let s = frames.len();
    let maps = GaussianMaps::from_raw(Tensor::from_data(TensorData::new(raw, [1, s, height, width, 12]), device));
    let depth = Tensor::from_data(TensorData::new(depth, [1, s, height, width]), device);
    let dynamic = Tensor::from_data(TensorData::new(dynamic, [1, s, height, width]), device);
    let views = frames.iter().map(|&frame| view(synth, frame)).collect();
    let pixels =
        PixelGaussians::new(&maps, depth, Some(dynamic), views, MeansGradient::Detached, PixelConvention::Centred)
            .unwrap()
            .with_instances(&InstanceSettings::default())
            .unwrap();
    let assembly = AssemblySettings { dynamic_motion: DynamicMotion::Instances, ..AssemblySettings::default() };
    Scene4d { pixels, sky: None, assembly }
}

/// The generator's render of `frame` as interleaved RGB in `[0, 1]`.
pub fn truth(synth: &SynthScene, frame: usize) -> Vec<f32> {
    synth.render_view(frame, 0).unwrap().image.as_raw().iter().map(|&v| v as f32 / 255.0).collect()
}

/// The pixels of `frame` where the ray meets object `object`.
pub fn object_mask(synth: &SynthScene, frame: usize, object: u32) -> Vec<bool> {
    let size = synth.image_size();
    let pose = synth.world_from_camera(frame, 0).unwrap();
    let at = synth.at(SynthConfig::frame_time(frame)).unwrap();
    let k = synth.intrinsics();
    (0..size.area())
        .map(|i| {
            let pixel = PixelConvention::Centred
                .coordinates((i % size.width as usize) as u32, (i / size.width as usize) as u32);
            let along = DVec3::new((pixel.x - k.cx) / k.fx, (pixel.y - k.cy) / k.fy, 1.0);
            at.cast(pose.translation(), pose.transform_vector(along)).is_some_and(|hit| hit.object == object)
        })
        .collect()
}

/// PSNR (dB) of `a` against `b` (interleaved RGB) over the pixels of `mask`.
pub fn masked_psnr(a: &[f32], b: &[f32], mask: &[bool]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for (pixel, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        for k in 0..3 {
            sum += ((a[pixel * 3 + k] - b[pixel * 3 + k]) as f64).powi(2);
        }
        count += 3;
    }
    -10.0 * (sum / count as f64).log10()
}

/// A render's colours on the host, clamped to `[0, 1]`.
pub fn colours(render: dggt_scene::ViewRender) -> Vec<f32> {
    render.rgb.into_data().try_into_vec::<f32>().unwrap().into_iter().map(|v| v.clamp(0.0, 1.0)).collect()
}

/// The world-axis-aligned box around a parked object, from just above the road to above its roof, as
/// `X0,Y0,Z0,X1,Y1,Z1` for `--remove-box`.
pub fn box_around(object: &dggt_synth::SceneObject) -> String {
    let [length, width, height] = object.box_size();
    let centre = object.centre(0.0);
    let half = 0.5 * (length * length + width * width).sqrt() + 0.1;
    let (low, high) = (centre - DVec3::new(half, half, 0.0), centre + DVec3::new(half, half, 0.0));
    format!("{},{},{},{},{},{}", low.x, low.y, 0.05, high.x, high.y, height + 0.2)
}

/// The parked car of `synth` that covers most of `frame`.
pub fn largest_parked_car(synth: &SynthScene, frame: usize) -> &dggt_synth::SceneObject {
    synth
        .instances()
        .filter(|object| object.motion().is_none())
        .max_by_key(|object| object_mask(synth, frame, object.id()).iter().filter(|m| **m).count())
        .expect("the scene has parked cars")
}
