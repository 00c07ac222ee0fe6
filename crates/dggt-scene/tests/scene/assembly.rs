//! Scene assembly on small synthetic predictions: culling never changes the render, gradients reach the maps
//! (and the depth only when asked), dynamic Gaussians appear only near their own time (cross-faded between the
//! two bracketing views when asked), lifespans fade, `eps2d` spreads every footprint.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::random::SplitMix64;
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{PinholeIntrinsics, PixelConvention, PosedCamera, WorldFromCamera};
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_scene::{
    AssemblySettings, DynamicBlend, DynamicMotion, HiddenSky, InputView, MeansGradient, PixelGaussians, TargetView,
    assemble, interpolate_camera, render_target, render_targets,
};
use dggt_splat::OpacityTensor;

const W: usize = 24;
const H: usize = 16;
const S: usize = 3;

fn camera(x: f64, yaw: f64) -> PosedCamera {
    PosedCamera {
        world_from_camera: WorldFromCamera::from_rotation_translation(
            DQuat::from_rotation_y(yaw),
            DVec3::new(x, 0.0, 0.0),
        )
        .unwrap(),
        intrinsics: PinholeIntrinsics::new(20.0, 20.0, W as f64 / 2.0, H as f64 / 2.0).unwrap(),
    }
}

fn views() -> Vec<InputView> {
    (0..S).map(|i| InputView { rig_camera: 0, time: i as f64 * 0.5, camera: camera(i as f64 * 0.3, 0.0) }).collect()
}

/// Deterministic pseudo-random values in `[-1, 1)`.
fn noise(count: usize, seed: u64) -> Vec<f32> {
    SplitMix64::new(seed).ranges(count, -1.0, 1.0)
}

/// Raw head output `[1, S, H, W, 12]`: visible colours, mostly opaque, small scales, short or long lifespans.
fn raw_maps(device: &Device, lifespan_raw: f32) -> Tensor<5> {
    let values = noise(S * H * W * 12, 7);
    let shaped: Vec<f32> = values
        .chunks_exact(12)
        .flat_map(|c| {
            let mut v = c.to_vec();
            v[3] = 2.0 + c[3]; // opacity logit
            for s in &mut v[4..7] {
                *s = -2.5 + 0.3 * *s; // 0.1 softplus -> ~0.008
            }
            v[7] += 2.0; // rotation near identity
            v[11] = lifespan_raw + 0.1 * c[11];
            v
        })
        .collect();
    Tensor::from_data(TensorData::new(shaped, [1, S, H, W, 12]), device)
}

fn depth(device: &Device) -> Tensor<4> {
    let values: Vec<f32> = noise(S * H * W, 3).iter().map(|v| 4.0 + v).collect();
    Tensor::from_data(TensorData::new(values, [1, S, H, W]), device)
}

fn logits(device: &Device, value: f32) -> Tensor<4> {
    Tensor::full([1, S, H, W], value, device)
}

/// The Gaussians of `maps` on `views` with the usual depth, dynamic logits of `dynamic_logit` (none when
/// `None`), means detached, unprojected at integer pixels.
fn placed(maps: &GaussianMaps, dynamic_logit: Option<f32>, views: Vec<InputView>) -> PixelGaussians {
    let device = maps.opacity.device();
    let logits = dynamic_logit.map(|value| logits(&device, value));
    PixelGaussians::new(maps, depth(&device), logits, views, MeansGradient::Detached, PixelConvention::Integer).unwrap()
}

/// The Gaussians of `maps` on `views()`, all static, means detached, unprojected at pixel centres.
fn static_at_pixel_centres(maps: &GaussianMaps) -> PixelGaussians {
    let device = maps.opacity.device();
    PixelGaussians::new(maps, depth(&device), None, views(), MeansGradient::Detached, PixelConvention::Centred).unwrap()
}

fn host(tensor: Tensor<3>) -> Vec<f32> {
    tensor.into_data().try_into_vec::<f32>().unwrap()
}

#[test]
fn culling_keeps_the_render_and_drops_what_cannot_show() {
    let device = Device::flex();
    // Lifespan raw 4 -> gamma 0.25: frames 0.5 apart fade to a tenth or less.
    let maps = GaussianMaps::from_raw(raw_maps(&device, 4.0));
    let pixels = placed(&maps, Some(-3.0), views());
    // Turned away from the last views: some Gaussians fall off screen.
    let target = TargetView { rig_camera: 0, time: 0.2, camera: camera(0.1, 0.5) };
    let culled = render_target(&pixels, None, &target, &AssemblySettings::default()).unwrap();
    let exact = render_target(&pixels, None, &target, &AssemblySettings::exact()).unwrap();
    assert!(culled.counts.transparent > 0 && culled.counts.off_screen > 0, "{:?}", culled.counts);
    assert_eq!(exact.counts.kept(), S * H * W + H * W);
    assert!(culled.counts.kept() < exact.counts.kept() / 2, "{:?}", culled.counts);
    let (a, b) = (host(culled.rgb), host(exact.rgb));
    let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "culling changed the render by {worst}");
    assert!(a.iter().any(|v| *v > 0.05), "the render is not empty");
}

#[test]
fn dynamic_gaussians_come_from_the_nearest_view_only() {
    let device = Device::flex();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 0.0));
    // Everything dynamic: only the nearest view's Gaussians survive (static opacity ~ 0).
    let pixels = placed(&maps, Some(12.0), views());
    let target = TargetView { rig_camera: 0, time: 0.9, camera: interpolate_camera(&pixels.views, 0, 0.9).unwrap() };
    let assembled = assemble(&pixels, &target, &AssemblySettings::default()).unwrap();
    assert_eq!(assembled.counts.static_kept, 0, "{:?}", assembled.counts);
    assert!(assembled.counts.dynamic_kept > H * W / 2, "{:?}", assembled.counts);
    // Without a dynamic head everything is static and long-lived (raw lifespan <= 0 -> gamma 1e6).
    let pixels = placed(&maps, None, views());
    let assembled = assemble(&pixels, &target, &AssemblySettings::default()).unwrap();
    assert_eq!(assembled.counts.dynamic_kept, 0);
    assert!(assembled.counts.static_kept > S * H * W / 2, "{:?}", assembled.counts);
}

#[test]
fn cross_fades_weigh_the_two_bracketing_views_dynamic_gaussians_by_time() {
    let device = Device::flex();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 0.0));
    let pixels = placed(&maps, Some(12.0), views());
    let per_view = H * W;
    let dynamic: Vec<f32> = {
        let logit = pixels.dynamic_logit.clone().expect("dynamic logits");
        let opacity = dggt_model::lifespan::dynamic_opacity(pixels.opacity.clone(), logit);
        opacity.into_data().try_into_vec().unwrap()
    };
    let view_sum = |view: usize| dynamic[view * per_view..(view + 1) * per_view].iter().map(|&o| o as f64).sum::<f64>();
    // Views at times 0, 0.5, 1: time 0.125 lies a quarter of the way from view 0 to view 1.
    let fade = AssemblySettings { dynamic_blend: DynamicBlend::CrossFade, ..AssemblySettings::exact() };
    let target =
        TargetView { rig_camera: 0, time: 0.125, camera: interpolate_camera(&pixels.views, 0, 0.125).unwrap() };
    let assembled = assemble(&pixels, &target, &fade).unwrap();
    assert_eq!(assembled.counts.dynamic_kept, 2 * per_view, "{:?}", assembled.counts);
    let OpacityTensor::Shared(opacities) = assembled.gaussians.opacities else { panic!("shared opacities") };
    let opacities: Vec<f32> = opacities.into_data().try_into_vec().unwrap();
    let drawn = |range: std::ops::Range<usize>| opacities[range].iter().map(|&o| o as f64).sum::<f64>();
    let statics = S * per_view;
    let (earlier, later) = (drawn(statics..statics + per_view), drawn(statics + per_view..statics + 2 * per_view));
    assert!((earlier - 0.75 * view_sum(0)).abs() < 1e-3 * earlier, "{earlier} vs 0.75 x {}", view_sum(0));
    assert!((later - 0.25 * view_sum(1)).abs() < 1e-3 * later, "{later} vs 0.25 x {}", view_sum(1));
    // At an input's own time only that view's dynamic Gaussians are drawn, at full opacity.
    let target = TargetView { rig_camera: 0, time: 0.5, camera: interpolate_camera(&pixels.views, 0, 0.5).unwrap() };
    let assembled = assemble(&pixels, &target, &fade).unwrap();
    assert_eq!(assembled.counts.dynamic_kept, per_view, "{:?}", assembled.counts);
    let OpacityTensor::Shared(opacities) = assembled.gaussians.opacities else { panic!("shared opacities") };
    let opacities: Vec<f32> = opacities.into_data().try_into_vec().unwrap();
    let own = opacities[statics..].iter().map(|&o| o as f64).sum::<f64>();
    assert!((own - view_sum(1)).abs() < 1e-3 * own, "{own} vs {}", view_sum(1));
}

#[test]
fn gradients_reach_the_maps_and_the_depth_only_when_asked() {
    let device = Device::flex().autodiff();
    for mode in [MeansGradient::Detached, MeansGradient::Through] {
        let raw = raw_maps(&device, 1.0).require_grad();
        let depth = depth(&device).require_grad();
        let maps = GaussianMaps::from_raw(raw.clone());
        let pixels = PixelGaussians::new(
            &maps,
            depth.clone(),
            Some(logits(&device, -1.0)),
            views(),
            mode,
            PixelConvention::Integer,
        )
        .unwrap();
        let target =
            TargetView { rig_camera: 0, time: 0.25, camera: interpolate_camera(&pixels.views, 0, 0.25).unwrap() };
        let view = render_target(&pixels, None, &target, &AssemblySettings::default()).unwrap();
        let grads = view.rgb.powi_scalar(2).sum().backward();
        let raw_grad: Vec<f32> = raw.grad(&grads).expect("maps gradient").into_data().try_into_vec().unwrap();
        assert!(raw_grad.iter().all(|g| g.is_finite()) && raw_grad.iter().any(|g| *g != 0.0));
        let depth_grad = depth.grad(&grads);
        match mode {
            MeansGradient::Detached => {
                let zero = depth_grad.map(|g| g.abs().max().into_scalar::<f32>() == 0.0).unwrap_or(true);
                assert!(zero, "detached means must not train the depth");
            }
            MeansGradient::Through => {
                let g: Vec<f32> = depth_grad.expect("depth gradient").into_data().try_into_vec().unwrap();
                assert!(g.iter().all(|v| v.is_finite()) && g.iter().any(|v| *v != 0.0));
            }
        }
    }
}

#[test]
fn bad_inputs_are_errors() {
    let device = Device::flex();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 1.0));
    let short = views()[..2].to_vec();
    assert!(
        PixelGaussians::new(&maps, depth(&device), None, short, MeansGradient::Detached, PixelConvention::Integer)
            .is_err()
    );
    let nan = Tensor::<4>::full([1, S, H, W], f32::NAN, &device);
    let error =
        PixelGaussians::new(&maps, nan, None, views(), MeansGradient::Detached, PixelConvention::Integer).unwrap_err();
    assert!(error.to_string().contains("depth"), "{error}");
    let wrong = Tensor::<4>::zeros([1, S, H, W + 1], &device);
    assert!(
        PixelGaussians::new(&maps, wrong, None, views(), MeansGradient::Detached, PixelConvention::Integer).is_err()
    );
}

#[test]
fn gaussians_beyond_the_far_plane_are_dropped_and_draw_nothing() {
    let device = Device::flex();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 0.0));
    let pixels = static_at_pixel_centres(&maps);
    let target = TargetView { rig_camera: 0, time: 0.5, camera: views()[1].camera };
    // Every depth lies in [4, 5) in front of cameras a few decimetres apart.
    let near = AssemblySettings { far_plane: 3.0, ..AssemblySettings::default() };
    let assembled = assemble(&pixels, &target, &near).unwrap();
    assert_eq!(assembled.counts.kept(), 0, "{:?}", assembled.counts);
    assert!(assembled.counts.off_screen > 0, "{:?}", assembled.counts);
    let view = render_target(&pixels, None, &target, &near).unwrap();
    assert!(host(view.alpha).iter().all(|a| *a == 0.0), "nothing drawn");
    let far = AssemblySettings { far_plane: 100.0, ..AssemblySettings::default() };
    assert_eq!(
        assemble(&pixels, &target, &far).unwrap().counts,
        assemble(&pixels, &target, &AssemblySettings::default()).unwrap().counts
    );
    let alpha = host(render_target(&pixels, None, &target, &far).unwrap().alpha);
    assert!(alpha.iter().filter(|a| **a > 0.5).count() > H * W / 2);
}

#[test]
fn eps2d_sets_how_far_each_footprint_spreads() {
    let device = Device::flex();
    // Tiny scales and short lifespans (gamma 0.25): at view 0's own time and camera, its Gaussians sit on the
    // pixel centres and the other views' have faded below the rasteriser's threshold.
    let maps = GaussianMaps::from_raw(raw_maps(&device, 4.0));
    let pixels = static_at_pixel_centres(&maps);
    let target = TargetView { rig_camera: 0, time: 0.0, camera: views()[0].camera };
    let own: Vec<f32> = {
        let opacity = host(maps.opacity.clone().narrow(1, 0, 1).reshape([H, W, 1]));
        let rgb = host(maps.rgb.narrow(1, 0, 1).reshape([H, W, 3]));
        rgb.iter().enumerate().map(|(i, c)| c * opacity[i / 3]).collect()
    };
    let mean_error = |eps2d: f32| {
        let settings = AssemblySettings { eps2d, ..AssemblySettings::default() };
        let rgb = host(render_target(&pixels, None, &target, &settings).unwrap().rgb);
        rgb.iter().zip(&own).map(|(a, b)| (a - b).abs()).sum::<f32>() / own.len() as f32
    };
    // The release's 0.3 px² spreads a fifth of each Gaussian's alpha onto its neighbours' centres; 0.03 px²
    // keeps each pixel to its own Gaussian.
    let (release, sharp) = (mean_error(0.3), mean_error(0.03));
    assert!(sharp < 1e-3, "with eps2d 0.03 each pixel shows its own Gaussian: mean error {sharp}");
    assert!(release > 0.02, "with eps2d 0.3 the neighbours blend in: mean error {release}");
    assert_eq!(AssemblySettings::default().eps2d, 0.3, "the release's low-pass variance is the default");
}

/// `[1, S, H, W, 3]` camera-axis velocities: view `v` moves everything along `(1, -0.5, 2) (v + 1)`.
fn velocity(device: &Device) -> Tensor<5> {
    let values: Vec<f32> =
        (0..S).flat_map(|v| (0..H * W).flat_map(move |_| [1.0, -0.5, 2.0].map(|c| c * (v + 1) as f32))).collect();
    Tensor::from_data(TensorData::new(values, [1, S, H, W, 3]), device)
}

#[test]
fn the_motion_head_moves_dynamic_gaussians_to_the_target_time() {
    let device = Device::flex();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 0.0));
    // Views turned by different yaws, so that camera axes differ from world axes.
    let turned: Vec<InputView> = views()
        .into_iter()
        .enumerate()
        .map(|(i, v)| InputView { camera: camera(i as f64 * 0.3, 0.2 * i as f64 - 0.1), ..v })
        .collect();
    let place = |logit: f32| {
        PixelGaussians::new(
            &maps,
            depth(&device),
            Some(logits(&device, logit)),
            turned.clone(),
            MeansGradient::Detached,
            PixelConvention::Integer,
        )
        .unwrap()
    };
    let frames_per_time = 6.0;
    // Everything dynamic; the target at 0.9 takes view 2 (time 1.0) as its nearest, 0.1 of scene time back.
    let held = place(12.0);
    let moving = place(12.0).with_motion(velocity(&device), frames_per_time).unwrap();
    let target = TargetView { rig_camera: 0, time: 0.9, camera: interpolate_camera(&turned, 0, 0.9).unwrap() };
    let exact = AssemblySettings::exact();
    let (a, b) = (assemble(&held, &target, &exact).unwrap(), assemble(&moving, &target, &exact).unwrap());
    let means = |g: &dggt_scene::AssembledGaussians| -> Vec<f32> {
        g.gaussians.means.clone().into_data().try_into_vec::<f32>().unwrap()
    };
    let (held_means, moved_means) = (means(&a), means(&b));
    // Statics first (every pixel, not moved), then the H W dynamic ones of view 2, moved by
    // R_world_from_camera (3, -1.5, 6) · 6 frames per unit time · (0.9 - 1.0).
    let statics = S * H * W * 3;
    assert_eq!(held_means.len(), moved_means.len());
    assert_eq!(&held_means[..statics], &moved_means[..statics], "static Gaussians do not move");
    let rotation = turned[2].camera.world_from_camera.rotation();
    let expected = rotation * (dggt_geom::glam::DVec3::new(3.0, -1.5, 6.0) * frames_per_time * (0.9 - 1.0));
    for (h, m) in held_means[statics..].chunks_exact(3).zip(moved_means[statics..].chunks_exact(3)) {
        for k in 0..3 {
            assert!(
                ((m[k] - h[k]) as f64 - expected[k]).abs() < 1e-4,
                "moved by {:?}, expected {expected}",
                [m[0] - h[0], m[1] - h[1], m[2] - h[2]]
            );
        }
    }
    // Held motion ignores the velocities: the moving pixels assemble as the still ones, and their flow is zero.
    let held_motion = AssemblySettings { dynamic_motion: DynamicMotion::Held, ..exact };
    assert_eq!(means(&assemble(&moving, &target, &held_motion).unwrap()), held_means);
    let still = dggt_scene::assembled_velocities(&moving, &target, &held_motion).unwrap();
    assert!(still.iter().flatten().all(|&v| v == 0.0), "held Gaussians have no velocity");
    // At an input's own time nothing moves.
    let at_input = TargetView { rig_camera: 0, time: 1.0, camera: turned[2].camera };
    let (a, b) = (assemble(&held, &at_input, &exact).unwrap(), assemble(&moving, &at_input, &exact).unwrap());
    assert_eq!(means(&a), means(&b));

    // Cross-faded, each of the two bracketing views moves over its own time to the target: view 1 (time 0.5)
    // forward by 0.4, view 2 (time 1.0) back by 0.1.
    let fade = AssemblySettings { dynamic_blend: DynamicBlend::CrossFade, ..exact };
    let (a, b) = (assemble(&held, &target, &fade).unwrap(), assemble(&moving, &target, &fade).unwrap());
    let (held_means, moved_means) = (means(&a), means(&b));
    assert_eq!(held_means.len(), statics + 2 * H * W * 3);
    for (view, elapsed, range) in
        [(1, 0.4, statics..statics + H * W * 3), (2, -0.1, statics + H * W * 3..held_means.len())]
    {
        let rotation = turned[view].camera.world_from_camera.rotation();
        let camera_velocity = dggt_geom::glam::DVec3::new(1.0, -0.5, 2.0) * (view + 1) as f64;
        let expected = rotation * (camera_velocity * frames_per_time * elapsed);
        for (h, m) in held_means[range.clone()].chunks_exact(3).zip(moved_means[range].chunks_exact(3)) {
            let moved = dggt_geom::glam::DVec3::new((m[0] - h[0]) as f64, (m[1] - h[1]) as f64, (m[2] - h[2]) as f64);
            assert!((moved - expected).length() < 1e-4, "view {view} moved by {moved}, expected {expected}");
        }
    }
}

#[test]
fn velocities_are_trained_by_renders_between_inputs() {
    let device = Device::flex().autodiff();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 0.0));
    let velocity = velocity(&device).mul_scalar(0.01).require_grad();
    let pixels = placed(&maps, Some(12.0), views()).with_motion(velocity.clone(), 4.0).unwrap();
    let target = TargetView { rig_camera: 0, time: 0.3, camera: interpolate_camera(&pixels.views, 0, 0.3).unwrap() };
    let view = render_target(&pixels, None, &target, &AssemblySettings::default()).unwrap();
    let grads = view.rgb.powi_scalar(2).sum().backward();
    let g: Vec<f32> = velocity.grad(&grads).expect("velocity gradient").into_data().try_into_vec().unwrap();
    assert!(g.iter().all(|v| v.is_finite()));
    // Only the nearest view's (view 1, time 0.5) velocities move anything.
    let per_view = H * W * 3;
    assert!(g[per_view..2 * per_view].iter().any(|v| *v != 0.0), "view 1 gets a gradient");
    assert!(g[..per_view].iter().chain(&g[2 * per_view..]).all(|v| *v == 0.0), "other views get none");
}

#[test]
fn bad_velocities_are_errors() {
    let device = Device::flex();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 0.0));
    let pixels = || placed(&maps, None, views());
    let wrong = Tensor::<5>::zeros([1, S, H, W, 2], &device);
    let error = pixels().with_motion(wrong, 1.0).unwrap_err().to_string();
    assert!(error.contains("velocity"), "{error}");
    let nan = velocity(&device).mul_scalar(f32::NAN);
    let error = pixels().with_motion(nan, 1.0).unwrap_err().to_string();
    assert!(error.contains("velocity"), "{error}");
    assert!(pixels().with_motion(velocity(&device), f64::INFINITY).is_err());
}

#[test]
fn velocities_of_pixels_too_still_to_draw_change_no_render() {
    // Dynamic logits at the motion-skip bound: sigmoid(-5.6) < 1/255, so no dynamic Gaussian is drawn, and
    // zero velocities (a skipped motion head) render exactly as predicted ones.
    let device = Device::flex();
    let maps = GaussianMaps::from_raw(raw_maps(&device, 0.0));
    assert!(below_the_alpha_threshold(-5.6));
    let place = || placed(&maps, Some(-5.6), views());
    let predicted = place().with_motion(velocity(&device), 6.0).unwrap();
    let skipped = place().with_motion(Tensor::zeros([1, S, H, W, 3], &device), 6.0).unwrap();
    for (time, blend) in [(0.9, DynamicBlend::Nearest), (0.7, DynamicBlend::CrossFade)] {
        let target = TargetView { rig_camera: 0, time, camera: interpolate_camera(&views(), 0, time).unwrap() };
        let settings = AssemblySettings { dynamic_blend: blend, ..AssemblySettings::exact() };
        let a = render_target(&predicted, None, &target, &settings).unwrap();
        let b = render_target(&skipped, None, &target, &settings).unwrap();
        assert_eq!(host(a.rgb), host(b.rgb), "t = {time}");
        assert_eq!(host(a.alpha), host(b.alpha), "t = {time}");
    }
}

/// `sigmoid(logit)` under the rasteriser's alpha threshold (the motion-skip rule of `dggt_infer::is_still`).
fn below_the_alpha_threshold(logit: f32) -> bool {
    1.0 / (1.0 + (-logit).exp()) < dggt_splat::constants::ALPHA_THRESHOLD
}

/// The Gaussians of `raw_maps` with every opacity logit at `logit` and scales ~0.3 (1.5 pixels at their depth):
/// opaque ones cover a view from the input cameras.
fn with_opacity(device: &Device, logit: f32) -> PixelGaussians {
    let raw = raw_maps(device, 0.0);
    let [b, s, h, w, _] = raw.dims();
    let channels = vec![
        raw.clone().narrow(4, 0, 3),
        Tensor::full([b, s, h, w, 1], logit, device),
        Tensor::full([b, s, h, w, 3], 3.0, device),
        raw.narrow(4, 7, 5),
    ];
    placed(&GaussianMaps::from_raw(Tensor::<5>::cat(channels, 4)), None, views())
}

/// One wide, nearly opaque sky Gaussian 50 units ahead of the first camera.
fn wide_sky(device: &Device) -> dggt_model::sky::SkyGaussians {
    dggt_model::sky::SkyGaussians {
        visible_index: vec![0],
        rgb_mean: Tensor::zeros([1, 3], device),
        field_out: Tensor::zeros([1, 6], device),
        means: Tensor::from_data(TensorData::new(vec![0.0f32, 0.0, 50.0], [1, 3]), device),
        quats: Tensor::from_data(TensorData::new(vec![1.0f32, 0.0, 0.0, 0.0], [1, 4]), device),
        scales: Tensor::full([1, 3], 100.0, device),
        opacities: Tensor::full([1], 0.99, device),
        colors: Tensor::full([1, 3], 0.8, device),
    }
}

#[test]
fn a_sky_the_foreground_covers_is_not_rendered_and_changes_the_image_below_the_tolerance() {
    let device = Device::flex();
    let (covered, faint) = (with_opacity(&device, 8.0), with_opacity(&device, -4.0));
    let sky = wide_sky(&device);
    let target = TargetView { rig_camera: 0, time: 0.5, camera: camera(0.3, 0.0) };
    let skip = AssemblySettings { hidden_sky: HiddenSky::BELOW_ONE_LEVEL, ..AssemblySettings::default() };
    let render = |pixels: &PixelGaussians, settings: &AssemblySettings| {
        render_target(pixels, Some(&sky), &target, settings).unwrap()
    };
    let (exact, skipped) = (render(&covered, &AssemblySettings::default()), render(&covered, &skip));
    assert!(exact.sky.is_some() && skipped.sky.is_none(), "a covered sky is skipped");
    let worst = host(exact.rgb).iter().zip(host(skipped.rgb)).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 0.8 / 255.0, "skipping the sky changed a colour by {worst}");
    // Where the sky shows through, it is rendered whatever the setting.
    assert!(render(&faint, &skip).sky.is_some());
}

#[test]
fn targets_rendered_together_are_each_target_rendered_alone() {
    let device = Device::flex();
    let pixels = with_opacity(&device, 8.0);
    let sky = wide_sky(&device);
    // From an input camera the opaque Gaussians cover the view; turned away, the sky shows.
    let targets = [
        TargetView { rig_camera: 0, time: 0.5, camera: camera(0.3, 0.0) },
        TargetView { rig_camera: 0, time: 0.2, camera: camera(0.1, 0.6) },
        TargetView { rig_camera: 0, time: 0.9, camera: camera(0.5, -0.4) },
    ];
    let skip = AssemblySettings { hidden_sky: HiddenSky::BELOW_ONE_LEVEL, ..AssemblySettings::default() };
    for settings in [AssemblySettings::default(), skip] {
        let together = render_targets(&pixels, Some(&sky), &targets, &settings).unwrap();
        assert_eq!(together.len(), targets.len());
        let mut skies = Vec::new();
        for (target, view) in targets.iter().zip(together) {
            let alone = render_target(&pixels, Some(&sky), target, &settings).unwrap();
            assert_eq!(view.counts, alone.counts);
            assert_eq!(view.sky.is_some(), alone.sky.is_some());
            skies.push(view.sky.is_some());
            assert_eq!(host(view.rgb), host(alone.rgb), "{settings:?} at t = {}", target.time);
            assert_eq!(host(view.alpha), host(alone.alpha));
        }
        match settings.hidden_sky {
            HiddenSky::Render => assert_eq!(skies, [true; 3]),
            HiddenSky::Skip { .. } => assert_eq!(skies, [false, true, true], "the covered view skips its sky"),
        }
    }
}
