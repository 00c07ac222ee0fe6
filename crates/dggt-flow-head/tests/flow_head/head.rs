//! The flow head's behaviour on `Device::flex()` in f32: a fresh head holds every point, empty clouds, scale
//! freedom, chunking, typed errors for bad input, and a small overfit with Adam.

use std::time::Instant;

use crate::common::{Host, HostCloud, Rng, randomised, small_config, values};
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsParams};
use burn::tensor::{Device, Tensor};
use dggt_flow_head::{CloudRole, FlowError, FlowHeadConfig, FlowHeadShape, FrameCloud};

/// `n` points uniform in `[0, extent)^3` with standard normal features.
fn random_cloud(n: usize, extent: f64, widths: usize, rng: &mut Rng) -> HostCloud {
    HostCloud {
        points: Host::new(n, 3, (0..3 * n).map(|_| rng.uniform(0.0, extent)).collect()),
        features: Host::new(n, widths, rng.normals(n * widths, 1.0)),
    }
}

fn clouds(config: &FlowHeadConfig, queries: usize, targets: usize, seed: u64) -> (HostCloud, HostCloud) {
    let mut rng = Rng::new(seed);
    let width = config.feature_width();
    (random_cloud(queries, 4.0, width, &mut rng), random_cloud(targets, 4.0, width, &mut rng))
}

fn empty(config: &FlowHeadConfig, device: &Device) -> FrameCloud {
    FrameCloud::new(Tensor::zeros([0, 3], device), Tensor::zeros([0, config.feature_width()], device))
}

#[test]
fn a_fresh_head_predicts_exactly_zero() {
    let device = Device::flex();
    let config = small_config();
    let (query, target) = clouds(&config, 12, 40, 1);
    let head = config.init(&device).unwrap();
    let flow = head.forward(&query.upload(&device), &target.upload(&device)).unwrap();
    assert_eq!(flow.dims(), [12, 3]);
    assert!(values(flow).iter().all(|v| *v == 0.0));
}

#[test]
fn empty_clouds() {
    let device = Device::flex();
    let config = small_config();
    let head = randomised(&config, 2, &device);
    let (query, target) = clouds(&config, 7, 20, 3);
    let (query, target) = (query.upload(&device), target.upload(&device));
    assert_eq!(head.forward(&empty(&config, &device), &target).unwrap().dims(), [0, 3]);
    let flow = head.forward(&query, &empty(&config, &device)).unwrap();
    assert_eq!(flow.dims(), [7, 3]);
    assert!(values(flow).iter().all(|v| *v == 0.0));
    // A head that moves points does move them when there is a target.
    assert!(values(head.forward(&query, &target).unwrap()).iter().any(|v| *v != 0.0));
}

#[test]
fn scaling_both_clouds_scales_the_displacement() {
    let device = Device::flex();
    let config = small_config();
    let head = randomised(&config, 4, &device);
    let (query, target) = clouds(&config, 30, 50, 5);
    let flow = |factor: f64| {
        let scale = |c: &HostCloud| HostCloud { points: c.points.scaled(factor), features: c.features.clone() };
        values(head.forward(&scale(&query).upload(&device), &scale(&target).upload(&device)).unwrap())
    };
    let (unit, tenfold) = (flow(1.0), flow(10.0));
    let largest = unit.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(largest > 1e-2, "the head moves the points: {largest}");
    for (a, b) in unit.iter().zip(&tenfold) {
        assert!((10.0 * a - b).abs() <= 1e-5 * 10.0 * largest, "{a} x 10 vs {b}");
    }
}

#[test]
fn chunking_does_not_change_the_result() {
    let device = Device::flex();
    let small_chunks = small_config();
    let mut one_chunk = small_config();
    one_chunk.shape.chunk = 8192;
    let (query, target) = clouds(&small_chunks, 23, 40, 6);
    let run = |config: &FlowHeadConfig| {
        let head = randomised(config, 7, &device);
        values(head.forward(&query.upload(&device), &target.upload(&device)).unwrap())
    };
    let (chunked, whole) = (run(&small_chunks), run(&one_chunk));
    for (a, b) in chunked.iter().zip(&whole) {
        assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{a} vs {b}");
    }
}

/// However large its update, the head moves no query further than the diagonal of the box holding both clouds.
#[test]
fn displacements_stay_within_the_clouds_extent() {
    let device = Device::flex();
    let config = small_config();
    let mut head = randomised(&config, 12, &device);
    let (query, target) = clouds(&config, 20, 30, 13);
    let diagonal = {
        let points: Vec<f64> = query.points.values.iter().chain(&target.points.values).copied().collect();
        let span = |axis: usize| {
            let values = points.iter().skip(axis).step_by(3);
            values.clone().fold(f64::MIN, |m, v| m.max(*v)) - values.fold(f64::MAX, |m, v| m.min(*v))
        };
        (0..3).map(|axis| span(axis).powi(2)).sum::<f64>().sqrt()
    };
    let (query, target) = (query.upload(&device), target.upload(&device));
    let lengths = |head: &dggt_flow_head::FlowHead| -> Vec<f64> {
        let flow = values(head.forward(&query, &target).unwrap());
        flow.chunks_exact(3).map(|d| d.iter().map(|v| v * v).sum::<f64>().sqrt()).collect()
    };
    let moderate = lengths(&head);
    assert!(moderate.iter().all(|&l| l < 0.5 * diagonal), "a moderate head is not capped: {moderate:?}");
    head.update.fc2 = head.update.fc2.clone().map(&mut Scaled(1e6));
    let huge = lengths(&head);
    assert!(huge.iter().all(|&l| l <= diagonal * (1.0 + 1e-5)), "{huge:?} vs {diagonal}");
    assert!(huge.iter().any(|&l| l > 0.99 * diagonal), "the update was large enough to reach the cap: {huge:?}");
    // Both clouds at one point: no extent, no motion, nothing non-finite.
    let point = |n: usize| {
        let cloud = HostCloud { points: Host::new(n, 3, vec![2.0; 3 * n]), features: query_features(n, &config) };
        cloud.upload(&device)
    };
    let flow = values(head.forward(&point(5), &point(7)).unwrap());
    assert!(flow.iter().all(|v| v.is_finite() && v.abs() < 1e-12), "{flow:?}");
}

/// `n` rows of standard normal features of the configuration's width.
fn query_features(n: usize, config: &FlowHeadConfig) -> Host {
    Host::new(n, config.feature_width(), Rng::new(14).normals(n * config.feature_width(), 1.0))
}

/// Multiplies every parameter by a factor.
struct Scaled(f32);

impl burn::module::ModuleMapper for Scaled {
    fn map_float<const D: usize>(&mut self, param: burn::module::Param<Tensor<D>>) -> burn::module::Param<Tensor<D>> {
        let factor = self.0;
        param.map(|old| old.mul_scalar(factor))
    }
}

#[test]
fn bad_input_is_named() {
    let device = Device::flex();
    let config = small_config();
    let head = config.init(&device).unwrap();
    let (query, target) = clouds(&config, 6, 10, 8);
    let (query, target) = (query.upload(&device), target.upload(&device));
    let with = |cloud: &FrameCloud, points: Option<Tensor<2>>, features: Option<Tensor<2>>| {
        FrameCloud::new(points.unwrap_or(cloud.points.clone()), features.unwrap_or(cloud.features.clone()))
    };
    let fewer_features = with(&target, None, Some(target.features.clone().narrow(0, 0, 9)));
    assert_eq!(
        head.forward(&query, &fewer_features).unwrap_err(),
        FlowError::RowMismatch { cloud: CloudRole::Target, points: 10, features: 9 }
    );
    let narrow_features = with(&query, None, Some(query.features.clone().narrow(1, 0, 4)));
    assert_eq!(
        head.forward(&narrow_features, &target).unwrap_err(),
        FlowError::FeatureWidth { cloud: CloudRole::Query, expected: 5, found: 4 }
    );
    let flat_points = with(&query, Some(query.points.clone().narrow(1, 0, 2)), None);
    assert_eq!(
        head.forward(&flat_points, &target).unwrap_err(),
        FlowError::PointWidth { cloud: CloudRole::Query, columns: 2 }
    );
    let mut nan = values(target.points.clone());
    nan[3 * 4 + 1] = f64::NAN;
    let nan_target = with(&target, Some(Host::new(10, 3, nan).tensor(&device)), None);
    let error = head.forward(&query, &nan_target).unwrap_err();
    assert!(matches!(error, FlowError::NonFinitePoint { cloud: CloudRole::Target, row: 4, .. }), "{error}");
    // Mismatched shapes are reported even when the other cloud is empty.
    assert!(matches!(head.forward(&empty(&config, &device), &fewer_features), Err(FlowError::RowMismatch { .. })));
}

/// Sets every parameter to NaN.
struct Poison;

impl burn::module::ModuleMapper for Poison {
    fn map_float<const D: usize>(&mut self, param: burn::module::Param<Tensor<D>>) -> burn::module::Param<Tensor<D>> {
        param.map(|old| old.zeros_like() + f32::NAN)
    }
}

/// The same error where the search runs on the host (positions read back every iteration) and, with the `wgpu`
/// feature, where it runs on the device (every iteration checked at once after the last).
#[test]
fn a_non_finite_displacement_stops_the_search() {
    let devices = [
        Device::flex(),
        #[cfg(feature = "wgpu")]
        Device::wgpu(burn::tensor::DeviceKind::default()),
    ];
    for device in devices {
        let config = small_config();
        let head = config.init(&device).unwrap().map(&mut Poison);
        let (query, target) = clouds(&config, 8, 10, 9);
        let error = head.forward(&query.upload(&device), &target.upload(&device)).unwrap_err();
        assert_eq!(error, FlowError::NonFiniteDisplacement { row: 0, iteration: 0 }, "on {device:?}");
    }
}

/// A target that is the query translated by `t`, features equal per point: a few hundred Adam steps bring the
/// mean displacement error below 10% of `|t|`.
#[test]
fn overfits_a_translation() {
    let device = Device::flex().autodiff();
    let config = FlowHeadConfig {
        feature_widths: vec![8],
        shape: FlowHeadShape { hidden: 32, heads: 4, neighbours: 8, iterations: 2, ..FlowHeadShape::default() },
    };
    let mut rng = Rng::new(10);
    let query = random_cloud(48, 4.0, 8, &mut rng);
    let shift = [0.3, -0.2, 0.25];
    let moved = query.points.values.iter().enumerate().map(|(i, v)| v + shift[i % 3]).collect();
    let target = HostCloud { points: Host::new(48, 3, moved), features: query.features.clone() };
    let (query, target) = (query.upload(&device), target.upload(&device));
    let shift_t = Host::new(1, 3, shift.to_vec()).tensor(&device);
    let norm = shift.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mean_error = |flow: Tensor<2>| (flow - shift_t.clone()).powi_scalar(2).sum_dim(1).sqrt().mean() / norm;
    let mut head = config.init(&device).unwrap();
    let mut optimizer = AdamConfig::new().init();
    let start = Instant::now();
    let initial = values(mean_error(head.forward(&query, &target).unwrap()))[0];
    for _ in 0..300 {
        let flow = head.forward(&query, &target).unwrap();
        let loss = (flow - shift_t.clone()).powi_scalar(2).mean() / (norm * norm);
        let grads = GradientsParams::from_grads(loss.backward(), &head);
        head = optimizer.step(3e-3, head, grads);
    }
    let error = values(mean_error(head.forward(&query, &target).unwrap()))[0];
    println!("mean error / |t|: {initial:.3} -> {error:.4} in {:.1?}", start.elapsed());
    assert!((initial - 1.0).abs() < 1e-6, "a fresh head holds the points: {initial}");
    assert!(error < 0.1, "mean error {error} of |t| after training");
}

/// A cloud prepared once serves as query and as target, with exactly the displacements of the unprepared calls;
/// its errors name its view.
#[test]
fn a_prepared_cloud_serves_both_roles() {
    let device = Device::flex();
    let config = small_config();
    let head = randomised(&config, 15, &device);
    let (a, b) = clouds(&config, 11, 13, 16);
    let (a, b) = (a.upload(&device), b.upload(&device));
    let prepared_a = head.prepare(&a, CloudRole::View(0)).unwrap();
    let prepared_b = head.prepare(&b, CloudRole::View(1)).unwrap();
    for ((query, target), (prepared_query, prepared_target)) in
        [((&a, &b), (&prepared_a, &prepared_b)), ((&b, &a), (&prepared_b, &prepared_a))]
    {
        let direct = values(head.forward(query, target).unwrap());
        assert!(direct.iter().any(|v| *v != 0.0));
        assert_eq!(values(head.forward_prepared(prepared_query, prepared_target).unwrap()), direct);
    }
    let mut points = values(b.points.clone());
    points[3 * 4 + 1] = f64::NAN;
    let broken = FrameCloud::new(Host::new(13, 3, points).tensor(&device), b.features);
    let error = head.prepare(&broken, CloudRole::View(1)).err().expect("a non-finite point is refused");
    assert!(matches!(error, FlowError::NonFinitePoint { cloud: CloudRole::View(1), row: 4, .. }), "{error}");
    assert!(error.to_string().contains("point 4 of the cloud of input view 1"), "{error}");
}
