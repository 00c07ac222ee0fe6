//! What each shortcut that skips what a scene does not need saves, where it fires, on the default CPU backend.
//!
//! `cargo bench --workspace --bench skips`:
//! - **motion**: the frame-chunked forward of the tiny network with a motion head (8 frames of 84x56, chunks
//!   of 4) with [`MotionPath::Always`] and [`MotionPath::WhereDynamic`], on a network whose instance head calls
//!   every pixel static (its last convolution set to a logit of -8), so that the motion head is skipped;
//! - **sky**: rendering one view whose foreground covers it over a 60 x 60 sky, with the sky rendered
//!   ([`HiddenSky::Render`]) and skipped ([`HiddenSky::BELOW_ONE_LEVEL`]).
//!
//! Medians of seven runs after a warm-up. On scenes where a shortcut does not fire it costs one host read of a
//! maximum (motion) or minimum (sky); `dggt bench --skips` measures that on a real export.

use burn::module::Param;
use burn::tensor::{Device, Distribution, Tensor};
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{PinholeIntrinsics, PixelConvention, PosedCamera, WorldFromCamera};
use dggt_infer::{MotionPath, forward_chunked};
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_model::sky::SkyGaussians;
use dggt_model::{Dggt, ModelConfig};
use dggt_scene::{AssemblySettings, HiddenSky, InputView, MeansGradient, PixelGaussians, TargetView, render_target};
use dggt_test_data::median_ms;

fn motion(device: &Device) {
    let mut model = Dggt::new(&ModelConfig::tiny().with_motion_head(), device).expect("tiny model builds");
    let out = &mut model.instance_head.as_mut().expect("the tiny model has an instance head").scratch.output_conv2.out;
    out.weight = Param::from_tensor(Tensor::zeros(out.weight.dims(), device));
    out.bias = Some(Param::from_tensor(Tensor::full([out.weight.dims()[0]], -8.0, device)));
    let images = Tensor::<5>::random([1, 8, 3, 56, 84], Distribution::Uniform(0.0, 1.0), device);
    println!("motion head, 8 frames of 84x56 in chunks of 4, every pixel static:");
    for motion in [MotionPath::Always, MotionPath::WhereDynamic] {
        let mut skipped = 0;
        let ms = median_ms(7, || {
            let prediction = forward_chunked(&model, images.clone(), 4, motion).expect("forward");
            skipped = prediction.motion_skipped_frames;
            let _ = prediction.depth.into_data();
        });
        println!("  {motion:?}: {ms:.1} ms (motion head skipped on {skipped} frames)");
    }
}

fn sky(device: &Device) {
    let (frames, height, width) = (3, 56, 84);
    // Gaussians of opacity 0.5 and scale 0.3 (4.5 pixels at depth 4) in front of every pixel, three layers deep:
    // the transmittance falls smoothly to the rasteriser's floor, so the foreground covers the view. (With
    // opaque ones it would stop at 1e-4 *before* a Gaussian that would take it lower, and can keep more.)
    let raw = Tensor::<5>::random([1, frames, height, width, 12], Distribution::Uniform(-0.5, 0.5), device);
    let [b, s, h, w, _] = raw.dims();
    let raw = Tensor::cat(
        vec![
            raw.clone().narrow(4, 0, 3),
            Tensor::full([b, s, h, w, 1], 0.0, device),
            Tensor::full([b, s, h, w, 3], 3.0, device),
            raw.narrow(4, 7, 5).add_scalar(0.5),
        ],
        4,
    );
    let camera = |x: f64| PosedCamera {
        world_from_camera: WorldFromCamera::from_rotation_translation(DQuat::IDENTITY, DVec3::new(x, 0.0, 0.0))
            .expect("a rigid pose"),
        intrinsics: PinholeIntrinsics::new(60.0, 60.0, width as f64 / 2.0, height as f64 / 2.0).expect("intrinsics"),
    };
    // Three views from one pose at one time: three layers of Gaussians in front of every pixel.
    let views: Vec<InputView> =
        (0..frames).map(|_| InputView { rig_camera: 0, time: 0.5, camera: camera(0.1) }).collect();
    let depth = Tensor::full([1, frames, height, width], 4.0, device);
    let pixels = PixelGaussians::new(
        &GaussianMaps::from_raw(raw),
        depth,
        None,
        views,
        MeansGradient::Detached,
        PixelConvention::Centred,
    )
    .expect("pixel Gaussians");
    let count = 3600;
    let sky = SkyGaussians {
        visible_index: (0..count).collect(),
        rgb_mean: Tensor::zeros([count, 3], device),
        field_out: Tensor::zeros([count, 6], device),
        colors: Tensor::full([count, 3], 0.7, device),
        means: Tensor::cat(
            vec![
                Tensor::random([count, 2], Distribution::Uniform(-40.0, 40.0), device),
                Tensor::full([count, 1], 40.0, device),
            ],
            1,
        ),
        scales: Tensor::full([count, 3], 3.0, device),
        quats: Tensor::cat(vec![Tensor::ones([count, 1], device), Tensor::zeros([count, 3], device)], 1),
        opacities: Tensor::full([count], 0.9, device),
    };
    let target = TargetView { rig_camera: 0, time: 0.5, camera: camera(0.1) };
    println!("sky behind a covered 84x56 view, {count} sky Gaussians:");
    for hidden_sky in [HiddenSky::Render, HiddenSky::BELOW_ONE_LEVEL] {
        let settings = AssemblySettings { hidden_sky, ..AssemblySettings::default() };
        let mut rendered = false;
        let ms = median_ms(7, || {
            let view = render_target(&pixels, Some(&sky), &target, &settings).expect("render");
            rendered = view.sky.is_some();
            let _ = view.rgb.into_data();
        });
        println!("  {hidden_sky:?}: {ms:.1} ms (sky rendered: {rendered})");
    }
}

fn main() {
    let device = Device::flex();
    device.seed(0);
    motion(&device);
    sky(&device);
}
