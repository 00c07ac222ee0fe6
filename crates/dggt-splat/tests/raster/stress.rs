//! Robustness: degenerate, huge, non-finite and badly placed Gaussians never panic and never produce a
//! non-finite output or gradient; malformed buffers are clear errors; results are bit-identical across runs
//! and thread counts.

use dggt_geom::ImageSize;
use dggt_splat::{
    CullReason, GaussianGrads, Gaussians, ImageGrads, Opacities, PinholeView, RasterSettings, Rasterized, SplatError,
    ViewBatch, rasterize, rasterize_backward,
};
use proptest::prelude::*;

use crate::scenes::{LossWeights, Rng, Scene, render_with_grads, view_at};

fn assert_all_finite(forward: &Rasterized, grads: &GaussianGrads) {
    let images = &forward.images;
    for (name, values) in [("colors", &images.colors), ("alpha", &images.alpha), ("depth", &images.depth)] {
        assert!(values.iter().all(|v| v.is_finite()), "non-finite {name} image");
    }
    let gradients = [
        ("means", grads.means.as_slice()),
        ("quats", &grads.quats),
        ("scales", &grads.scales),
        ("opacities", grads.opacities.values()),
        ("colors", &grads.colors),
        ("background", &grads.background),
    ];
    for (name, values) in gradients {
        assert!(values.iter().all(|v| v.is_finite()), "non-finite {name} gradient: {values:?}");
    }
}

fn two_views(size: ImageSize) -> ViewBatch {
    ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([0.5, -0.2, 0.1], 0.25, size)], size).unwrap()
}

/// Values that break naive arithmetic, mixed into ordinary ones.
fn wild() -> impl Strategy<Value = f32> {
    let specials = vec![
        0.0,
        -0.0,
        1e-45,
        f32::MIN_POSITIVE,
        1e-30,
        -1e-30,
        1e-8,
        1e8,
        1e30,
        -1e30,
        f32::MAX,
        -f32::MAX,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    prop_oneof![6 => -3.0f32..3.0, 1 => prop::sample::select(specials)]
}

/// A camera-space depth for a camera at the origin: in front, around the near plane, behind, or wild.
fn depth() -> impl Strategy<Value = f32> {
    let near = vec![0.0, 0.005, 0.01, 0.010_000_1, 0.011, 0.02, -1.0, 2e10];
    prop_oneof![4 => 1.0f32..8.0, 1 => prop::sample::select(near), 1 => wild()]
}

fn scale() -> impl Strategy<Value = f32> {
    prop_oneof![4 => 0.01f32..1.0, 1 => prop::sample::select(vec![0.0, 1e-8, 1e3, 1e20]), 1 => wild()]
}

fn quat() -> impl Strategy<Value = [f32; 4]> {
    prop_oneof![
        4 => prop::array::uniform4(-1.0f32..1.0),
        1 => Just([0.0; 4]),
        1 => Just([1e-20, 0.0, 0.0, 1e-20]),
        1 => prop::array::uniform4(wild()),
    ]
}

#[derive(Debug, Clone)]
struct WildGaussian {
    mean: [f32; 3],
    quat: [f32; 4],
    scale: [f32; 3],
    opacities: [f32; 2],
    color: [f32; 3],
}

fn wild_gaussian() -> impl Strategy<Value = WildGaussian> {
    let opacity = || prop_oneof![3 => 0.0f32..1.0, 1 => wild()];
    (
        (prop_oneof![3 => -2.0f32..2.0, 1 => wild()], prop_oneof![3 => -2.0f32..2.0, 1 => wild()], depth()),
        quat(),
        prop::array::uniform3(scale()),
        (opacity(), opacity()),
        prop::array::uniform3(prop_oneof![4 => -1.0f32..2.0, 1 => wild()]),
    )
        .prop_map(|((x, y, z), quat, scale, (o0, o1), color)| WildGaussian {
            mean: [x, y, z],
            quat,
            scale,
            opacities: [o0, o1],
            color,
        })
}

fn scene_of(gaussians: &[WildGaussian], per_view: bool) -> Scene {
    let opacities = if per_view {
        let row = |v: usize| gaussians.iter().map(move |g| g.opacities[v]);
        Opacities::PerView(row(0).chain(row(1)).collect())
    } else {
        Opacities::Shared(gaussians.iter().map(|g| g.opacities[0]).collect())
    };
    Scene {
        means: gaussians.iter().flat_map(|g| g.mean).collect(),
        quats: gaussians.iter().flat_map(|g| g.quat).collect(),
        scales: gaussians.iter().flat_map(|g| g.scale).collect(),
        opacities,
        colors: gaussians.iter().flat_map(|g| g.color).collect(),
        channels: 3,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn wild_scenes_stay_finite_and_deterministic(
        gaussians in prop::collection::vec(wild_gaussian(), 0..12),
        per_view in any::<bool>(),
        gradient_scale in prop::sample::select(vec![1.0f32, 1e-20, 1e20]),
        eps2d in prop::sample::select(vec![0.3f32, 0.0]),
        seed in any::<u64>(),
    ) {
        let size = ImageSize::new(24, 16).unwrap();
        let views = two_views(size);
        let scene = scene_of(&gaussians, per_view);
        let settings = RasterSettings { eps2d, background: Some(vec![0.3, 0.0, 1.0]), ..RasterSettings::default() };
        let mut weights = LossWeights::random(&mut Rng::new(seed), views.len(), size, 3);
        for w in weights.colors.iter_mut().chain(&mut weights.alpha).chain(&mut weights.depth) {
            *w *= gradient_scale;
        }
        let (forward, grads) = render_with_grads(&scene, &views, &settings, &weights);
        assert_all_finite(&forward, &grads);
        for stats in &forward.stats {
            prop_assert_eq!(stats.gaussians, gaussians.len());
            prop_assert_eq!(stats.kept + stats.culled(), gaussians.len());
        }
        let (again, grads_again) = render_with_grads(&scene, &views, &settings, &weights);
        prop_assert!(again == forward);
        prop_assert!(grads_again == grads);
    }
}

/// Mean, quaternion, scale, opacity, colour, and the expected outcome in view 0 (`None` = kept).
type DegenerateCase = ([f32; 3], [f32; 4], [f32; 3], f32, [f32; 3], Option<CullReason>);

#[test]
fn degenerate_gaussians_are_kept_or_culled_for_the_documented_reason() {
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    let cases: Vec<DegenerateCase> = vec![
        ([0.0, 0.0, 3.0], [0.0; 4], [0.2, 0.1, 0.3], 0.8, [1.0; 3], None),
        ([0.1, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.0; 3], 0.8, [1.0; 3], None),
        ([0.0, 0.1, 3.0], [0.3, 0.1, 0.0, 0.9], [1e-8, 1e3, 1.0], 0.5, [0.2; 3], None),
        ([0.0, 0.0, 4.0], [0.9, 0.1, 0.2, 0.3], [f32::MAX; 3], 0.5, [0.5; 3], None),
        ([0.0, 0.0, 4.0], [0.9, 0.1, 0.2, 0.3], [1e20, 1e-20, 1.0], 0.5, [0.5; 3], None),
        ([0.0, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 5.0, [0.5; 3], None),
        ([0.0, 0.0, 0.0101], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5; 3], None),
        ([0.0, 0.0, 0.01], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5; 3], Some(CullReason::NearPlane)),
        ([0.0, 0.0, -2.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5; 3], Some(CullReason::NearPlane)),
        ([0.0, 0.0, 2e10], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5; 3], Some(CullReason::FarPlane)),
        ([1e30, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5; 3], Some(CullReason::OutsideImage)),
        ([nan, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5; 3], Some(CullReason::NonFinite)),
        ([0.0, 0.0, 3.0], [inf, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5; 3], Some(CullReason::NonFinite)),
        ([0.0, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.3, nan, 0.3], 0.5, [0.5; 3], Some(CullReason::NonFinite)),
        ([0.0, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], inf, [0.5; 3], Some(CullReason::NonFinite)),
        ([0.0, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.5, [0.5, nan, 0.5], Some(CullReason::NonFinite)),
        ([0.0, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], -0.5, [0.5; 3], Some(CullReason::Transparent)),
        ([0.0, 0.0, 3.0], [1.0, 0.0, 0.0, 0.0], [0.3; 3], 0.003, [0.5; 3], Some(CullReason::Transparent)),
    ];
    let size = ImageSize::new(32, 24).unwrap();
    let views = two_views(size);
    let settings = RasterSettings::default();
    let mut rng = Rng::new(4);
    let weights = LossWeights::random(&mut rng, views.len(), size, 3);
    for (k, (mean, quat, scale, opacity, color, expected)) in cases.iter().enumerate() {
        // Each degenerate Gaussian together with an ordinary one in front of it and one behind.
        let mut scene = Scene::random(&mut rng, 2, 3, (0.1, 0.3));
        scene.means.extend(mean);
        scene.quats.extend(quat);
        scene.scales.extend(scale);
        let Opacities::Shared(opacities) = &mut scene.opacities else { unreachable!() };
        opacities.push(*opacity);
        scene.colors.extend(color);
        let (forward, grads) = render_with_grads(&scene, &views, &settings, &weights);
        assert_all_finite(&forward, &grads);
        assert_eq!(forward.projection.culled[2], *expected, "case {k}");
        if quat.iter().all(|q| *q == 0.0) {
            assert_eq!(grads.quats[8..], [0.0; 4], "a zero quaternion gets no gradient");
        }
    }
}

#[test]
fn results_are_bit_identical_across_runs_and_thread_counts() {
    let mut rng = Rng::new(21);
    let size = ImageSize::new(96, 64).unwrap();
    let views = two_views(size);
    let scene = Scene::random(&mut rng, 1500, 4, (0.02, 0.25));
    let settings = RasterSettings::default();
    let weights = LossWeights::random(&mut rng, views.len(), size, 4);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| render_with_grads(&scene, &views, &settings, &weights))
    };
    let (reference, reference_grads) = render_with_grads(&scene, &views, &settings, &weights);
    assert!(reference.stats.iter().all(|s| s.tile_intersections > 1000));
    for threads in [1, 3, 8] {
        let (forward, grads) = run(threads);
        assert!(forward == reference, "forward differs with {threads} threads");
        assert!(grads == reference_grads, "gradients differ with {threads} threads");
    }
}

fn error_text(result: Result<impl std::fmt::Debug, SplatError>) -> String {
    result.expect_err("expected an error").to_string()
}

#[test]
fn malformed_buffers_are_clear_errors() {
    let scene = Scene::random(&mut Rng::new(0), 4, 3, (0.1, 0.2));
    let (m, q, s, c) = (&scene.means[..], &scene.quats[..], &scene.scales[..], &scene.colors[..]);
    let o = [0.5f32; 4];
    let shared = Opacities::Shared(&o[..]);
    assert!(error_text(Gaussians::new(&m[..11], q, s, shared, c, 3)).contains("`means`"));
    assert!(error_text(Gaussians::new(m, &q[..15], s, shared, c, 3)).contains("`quats`"));
    assert!(error_text(Gaussians::new(m, q, &s[..3], shared, c, 3)).contains("`scales`"));
    assert!(error_text(Gaussians::new(m, q, s, shared, c, 4)).contains("`colors`"));
    assert!(error_text(Gaussians::new(m, q, s, shared, c, 0)).contains("`colors`"));
    assert!(error_text(Gaussians::new(m, q, s, Opacities::Shared(&o[..3]), c, 3)).contains("`opacities`"));

    let size = ImageSize::new(16, 16).unwrap();
    let views = two_views(size);
    let settings = RasterSettings::default();
    let per_view = Gaussians::new(m, q, s, Opacities::PerView(&o[..]), c, 3).unwrap();
    let message = error_text(rasterize(&per_view, &views, &settings));
    assert!(message.contains("`opacities`") && message.contains("[V, N]"), "{message}");

    let identity = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0f32];
    let k = [20.0, 0.0, 8.0, 0.0, 20.0, 8.0, 0.0, 0.0, 1.0f32];
    assert!(ViewBatch::from_matrices(&identity, &k, size).is_ok());
    assert!(error_text(ViewBatch::from_matrices(&identity[..15], &k, size)).contains("`viewmats`"));
    assert!(error_text(ViewBatch::from_matrices(&identity, &k[..8], size)).contains("`intrinsics`"));
    let mut projective = identity;
    projective[14] = 0.5;
    assert!(error_text(ViewBatch::from_matrices(&projective, &k, size)).contains("last row"));
    let bad_focal = PinholeView { fx: 0.0, ..view_at([0.0; 3], 0.0, size) };
    assert!(error_text(ViewBatch::new(vec![bad_focal], size)).contains("focal"));
    let nan_pose = PinholeView { world_to_camera: [[f32::NAN; 4]; 3], ..view_at([0.0; 3], 0.0, size) };
    assert!(error_text(ViewBatch::new(vec![nan_pose], size)).contains("non-finite"));

    let gaussians = scene.gaussians();
    let wrong_background = RasterSettings { background: Some(vec![0.0; 2]), ..RasterSettings::default() };
    assert!(error_text(rasterize(&gaussians, &views, &wrong_background)).contains("`background`"));
    let nan_background = RasterSettings { background: Some(vec![0.0, f32::NAN, 0.0]), ..RasterSettings::default() };
    assert!(error_text(rasterize(&gaussians, &views, &nan_background)).contains("`background`"));
    let inverted = RasterSettings { near_plane: 5.0, far_plane: 1.0, ..RasterSettings::default() };
    assert!(error_text(rasterize(&gaussians, &views, &inverted)).contains("far_plane"));
    let no_tiles = RasterSettings { tile_size: 0, ..RasterSettings::default() };
    assert!(error_text(rasterize(&gaussians, &views, &no_tiles)).contains("tile_size"));

    let forward = rasterize(&gaussians, &views, &settings).unwrap();
    let pixels = 2 * size.area();
    let short = vec![0.0f32; pixels - 1];
    let grads = ImageGrads { alpha: Some(&short), ..ImageGrads::default() };
    assert!(error_text(rasterize_backward(&gaussians, &views, &settings, &forward, &grads)).contains("`grad alpha`"));
    let mut nan = vec![0.0f32; pixels];
    nan[7] = f32::NAN;
    let grads = ImageGrads { depth: Some(&nan), ..ImageGrads::default() };
    assert!(error_text(rasterize_backward(&gaussians, &views, &settings, &forward, &grads)).contains("`grad depth`"));
    let fewer = Gaussians::new(&m[..9], &q[..12], &s[..9], Opacities::Shared(&o[..3]), &c[..9], 3).unwrap();
    let message = error_text(rasterize_backward(&fewer, &views, &settings, &forward, &ImageGrads::default()));
    assert!(message.contains("forward"), "{message}");
}
