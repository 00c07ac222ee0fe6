//! The head computes the attention its documentation describes: the displacement against a direct evaluation of
//! the documented formulas (every neighbour token `proj(f_j) + enc_o(o_j)` built, keyed and valued as written),
//! with every target point a neighbour so that the neighbour search plays no part. The head itself evaluates the
//! same attention factored (keys and values of the features projected once per target point, the offset
//! encoding's last layer folded into the key and value matrices); the two agree to f32 rounding.

use crate::common::{Host, HostCloud, Rng, parameter_gradients, randomised, values};
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Int, Tensor, TensorData};
use dggt_flow_head::attention::{self, AttentionKernel, AttentionTensors};
use dggt_flow_head::neighbours::NeighbourSearch;
use dggt_flow_head::scale::ScaleSource;
use dggt_flow_head::{FlowHead, FlowHeadConfig, FlowHeadShape, FrameCloud, HeadInputs};

/// The head's shape for the check: 3 heads of width 4, 2 iterations, every one of the 9 target points a
/// neighbour, chunks of 4 queries.
fn config(inputs: HeadInputs) -> FlowHeadConfig {
    FlowHeadConfig {
        feature_widths: vec![3, 2],
        shape: FlowHeadShape { hidden: 12, heads: 3, neighbours: 16, iterations: 2, chunk: 4, inputs },
    }
}

fn cloud(n: usize, widths: usize, rng: &mut Rng) -> HostCloud {
    HostCloud {
        points: Host::new(n, 3, (0..3 * n).map(|_| rng.uniform(-2.0, 2.0)).collect()),
        features: Host::new(n, widths, rng.normals(n * widths, 1.0)),
    }
}

/// The documented iteration, written out: `[N, 3]` displacements of `query` towards `target` (the clouds
/// uploaded from `hosts`), every target point attended to by every query.
fn documented_flow(
    head: &FlowHead,
    config: &FlowHeadConfig,
    (query, target): (&FrameCloud, &FrameCloud),
    hosts: (&HostCloud, &HostCloud),
) -> Tensor<2> {
    let host_targets: Vec<[f32; 3]> =
        hosts.1.points.values.chunks_exact(3).map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect();
    let scale = ScaleSource::of_target(&host_targets, &NeighbourSearch::new(&host_targets))
        .length(&query.points, &target.points);
    let scale = scale.reshape([1, 1]);
    let extent = diagonal(&hosts.0.points.values, &hosts.1.points.values);
    let (n, m) = (query.len(), target.len());
    let shape = &config.shape;
    let (hidden, heads) = (shape.hidden, shape.heads);
    let width = hidden / heads;
    let features = |f: Tensor<2>| match shape.inputs {
        HeadInputs::FeaturesAndOffsets => head.feature_in.forward(f),
        HeadInputs::OffsetsOnly => head.feature_in.forward(f.zeros_like()),
    };
    let target_tokens = features(target.features.clone()).unsqueeze_dim::<3>(0).repeat_dim(0, n);
    let mut state = features(query.features.clone());
    let mut displacement = query.points.zeros_like();
    for _ in 0..shape.iterations {
        let position = query.points.clone() + displacement.clone();
        // [N, M, 3]: every target point's offset from every query, in units of the spacing.
        let offsets = (target.points.clone().unsqueeze_dim::<3>(0).repeat_dim(0, n)
            - position.unsqueeze_dim::<3>(1).repeat_dim(1, m))
            / scale.clone().unsqueeze_dim::<3>(0);
        let tokens = target_tokens.clone() + head.offset_in.forward(offsets.clone());
        let query_token = state.clone() + head.state_in.forward(displacement.clone() / scale.clone());
        let q = head.query.forward(query_token).reshape([n, heads, 1, width]);
        let split = |t: Tensor<3>| t.reshape([n, m, heads, width]).swap_dims(1, 2);
        let keys = split(head.key.forward(tokens.clone()));
        let token_values = split(head.value.forward(tokens));
        let weights = softmax(q.matmul(keys.swap_dims(2, 3)) / (width as f64).sqrt(), 3);
        let attended = weights.clone().matmul(token_values).reshape([n, hidden]);
        let matched = weights.matmul(offsets.unsqueeze_dim::<4>(1).repeat_dim(1, heads)).reshape([n, 3 * heads]);
        state = state + head.merge.forward(Tensor::cat(vec![attended, matched], 1));
        displacement = capped(displacement + head.update.forward(state.clone()) * scale.clone(), extent);
    }
    displacement
}

/// The diagonal of the box holding both clouds' points (flattened `x y z` rows).
fn diagonal(query: &[f64], target: &[f64]) -> f64 {
    let span = |axis: usize| {
        let coordinates = query.iter().chain(target).skip(axis).step_by(3);
        coordinates.clone().fold(f64::MIN, |m, v| m.max(*v)) - coordinates.fold(f64::MAX, |m, v| m.min(*v))
    };
    (0..3).map(|axis| span(axis).powi(2)).sum::<f64>().sqrt()
}

/// Rows of `displacement` longer than `limit` shortened to it.
fn capped(displacement: Tensor<2>, limit: f64) -> Tensor<2> {
    let length = displacement.clone().powi_scalar(2).sum_dim(1).sqrt();
    displacement * length.div_scalar(limit).clamp_min(1.0).recip()
}

/// The head against the documented formulas: the displacements, and the gradients of a weighted sum of them with
/// respect to both clouds' points and features and to every parameter, all within 1e-5 of each tensor's largest
/// entry (f32 on `flex`, the fused op against burn's operations and autodiff).
fn check(inputs: HeadInputs, seed: u64) {
    let device = Device::flex().autodiff();
    let config = config(inputs);
    let head = randomised(&config, seed, &device);
    let mut rng = Rng::new(seed + 1);
    let hosts = (cloud(10, 5, &mut rng), cloud(9, 5, &mut rng));
    let weights = Host::new(10, 3, rng.normals(30, 1.0)).tensor(&device);
    let run = |flow: &dyn Fn(&FrameCloud, &FrameCloud) -> Tensor<2>| {
        let leaf = |h: &Host| h.tensor(&device).require_grad();
        let leaves = [leaf(&hosts.0.points), leaf(&hosts.0.features), leaf(&hosts.1.points), leaf(&hosts.1.features)];
        let query = FrameCloud::new(leaves[0].clone(), leaves[1].clone());
        let target = FrameCloud::new(leaves[2].clone(), leaves[3].clone());
        let displacement = flow(&query, &target);
        let grads = (displacement.clone() * weights.clone()).sum().backward();
        let mut found = vec![("displacement".to_string(), values(displacement))];
        for (name, leaf) in ["query points", "query features", "target points", "target features"].iter().zip(&leaves) {
            // None for the features when the head ignores them.
            found.push((name.to_string(), leaf.grad(&grads).map(values).unwrap_or_default()));
        }
        found.extend(parameter_gradients(&head, &grads).into_iter().map(|(path, _, grad)| (path, grad)));
        found
    };
    let expected = run(&|query, target| documented_flow(&head, &config, (query, target), (&hosts.0, &hosts.1)));
    let found = run(&|query, target| head.forward(query, target).unwrap());
    let moved = expected[0].1.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(moved > 1e-2, "the head moves the points: {moved}");
    assert_eq!(found.len(), expected.len(), "a gradient for every expected parameter");
    for ((name, found), (_, expected)) in found.iter().zip(&expected) {
        let largest = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if largest == 0.0 {
            assert!(found.iter().all(|v| *v == 0.0), "{name}: zero or absent by the formulas, not by the head");
            continue;
        }
        assert_eq!(found.len(), expected.len(), "{name}");
        for (i, (f, e)) in found.iter().zip(expected).enumerate() {
            assert!((f - e).abs() <= 1e-5 * largest, "{name}[{i}]: head {f}, formulas {e} (largest {largest})");
        }
    }
}

#[test]
fn the_head_computes_the_documented_attention() {
    check(HeadInputs::FeaturesAndOffsets, 20);
}

#[test]
fn the_offsets_only_head_computes_the_documented_attention() {
    check(HeadInputs::OffsetsOnly, 21);
}

/// A standard normal tensor that requires a gradient.
fn leaf<const D: usize>(shape: [usize; D], rng: &mut Rng, device: &Device) -> Tensor<D> {
    let values = rng.normals(shape.iter().product(), 1.0);
    Tensor::from_data(TensorData::new(values, shape), device).require_grad()
}

/// The sizes of one attention call.
#[derive(Debug, Clone, Copy)]
struct CallShape {
    queries: usize,
    neighbours: usize,
    targets: usize,
    heads: usize,
    width: usize,
    hidden: usize,
}

/// 7 queries of 5 neighbours among 6 target points, 2 heads of width 3, encodings of 6 channels.
const SMALL: CallShape = CallShape { queries: 7, neighbours: 5, targets: 6, heads: 2, width: 3, hidden: 6 };

/// Random inputs of one attention call of `shape`.
fn attention_inputs(shape: CallShape, device: &Device, rng: &mut Rng) -> AttentionTensors {
    let CallShape { queries: n, neighbours: k, targets, heads, width, hidden } = shape;
    let rows: Vec<i64> = (0..n * k).map(|_| (rng.unit() * targets as f64) as i64).collect();
    AttentionTensors {
        offsets: leaf([n, k, 3], rng, device),
        rows: Tensor::<2, Int>::from_data(TensorData::new(rows, [n, k]), device),
        keys_values: leaf([targets, 2 * heads * width], rng, device),
        encoder_weight: leaf([3, hidden], rng, device),
        encoder_bias: leaf([hidden], rng, device),
        queries: leaf([n, heads, width], rng, device),
        turned: leaf([n, heads, hidden], rng, device),
    }
}

/// The six float inputs' names, in the order [`run_op`] returns their gradients.
const INPUT_NAMES: [&str; 6] = ["offsets", "keys_values", "encoder_weight", "encoder_bias", "queries", "turned"];

/// One attention call of `shape` on `device` (seeded inputs, the same on every device) with `kernel`: its packed
/// output, and the gradients of every float input of the output's dot product with a seeded probe.
fn run_op(shape: CallShape, device: &Device, kernel: AttentionKernel) -> (Vec<f64>, Vec<Vec<f64>>) {
    let inputs = attention_inputs(shape, device, &mut Rng::new(30));
    let len = shape.queries * shape.heads * (shape.width + shape.hidden + 3);
    let probe = Tensor::<1>::from_data(TensorData::new(Rng::new(31).normals(len, 1.0), [len]), device);
    let out = attention::attend(inputs.clone(), kernel);
    let packed = Tensor::cat(vec![out.values, out.pooled, out.matched], 2).reshape([-1]);
    let grads = (packed.clone() * probe).sum().backward();
    let gradients = vec![
        values(inputs.offsets.grad(&grads).unwrap()),
        values(inputs.keys_values.grad(&grads).unwrap()),
        values(inputs.encoder_weight.grad(&grads).unwrap()),
        values(inputs.encoder_bias.grad(&grads).unwrap()),
        values(inputs.queries.grad(&grads).unwrap()),
        values(inputs.turned.grad(&grads).unwrap()),
    ];
    (values(packed), gradients)
}

/// The fused host op and the tensor operations (whose gradients `gradients_f64.rs` checks in f64) give the same
/// sums and the same gradients of every float input, on `flex` in f32.
#[test]
fn the_fused_op_matches_the_tensor_operations() {
    let device = Device::flex().autodiff();
    let (fused, fused_grads) = run_op(SMALL, &device, AttentionKernel::Fused);
    let (tensor, tensor_grads) = run_op(SMALL, &device, AttentionKernel::TensorOps);
    close(&fused, &tensor, "output", 1e-5);
    for ((name, f), t) in INPUT_NAMES.iter().zip(&fused_grads).zip(&tensor_grads) {
        close(f, t, name, 1e-5);
    }
}

/// Entry by entry within `tolerance` of the largest entry; returns the worst difference relative to it.
fn close(found: &[f64], expected: &[f64], what: &str, tolerance: f64) -> f64 {
    assert_eq!(found.len(), expected.len(), "{what}");
    let largest = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(largest > 0.0, "{what} is all zero");
    let mut worst = 0.0f64;
    for (i, (f, e)) in found.iter().zip(expected).enumerate() {
        assert!((f - e).abs() <= tolerance * largest, "{what}[{i}]: found {f}, expected {e}");
        worst = worst.max((f - e).abs() / largest);
    }
    worst
}

/// Shaped like the default head (16 neighbours, 4 heads of 16 channels, 64 encoding channels): every phase of
/// the device kernels takes several passes of a cube's units.
#[cfg(feature = "wgpu")]
const DEFAULT_HEAD: CallShape = CallShape { queries: 40, neighbours: 16, targets: 30, heads: 4, width: 16, hidden: 64 };

/// How closely the CubeCL kernels follow the host kernel, relative to each tensor's largest entry: to float
/// rounding (the device's `exp`, the order of the sums and of the atomic additions differ; seen on lavapipe: at
/// most 1.3e-6, the offsets' gradient of the default head's shape).
#[cfg(feature = "wgpu")]
const DEVICE_OP_TOLERANCE: f64 = 1e-5;

/// The fused op on wgpu (the CubeCL kernels, one cube per query) against the host kernel on `flex`: the output and
/// the six gradients, on a call within one pass of a cube's units and on one shaped like the default head.
#[cfg(feature = "wgpu")]
#[test]
fn the_device_kernels_match_the_host_kernel() {
    let wgpu = Device::wgpu(burn::tensor::DeviceKind::default()).autodiff();
    let flex = Device::flex().autodiff();
    for shape in [SMALL, DEFAULT_HEAD] {
        let probe = Tensor::<2>::zeros([1, shape.heads * shape.width], &wgpu);
        let kernel = AttentionKernel::for_queries(&probe, shape.neighbours, shape.heads);
        assert_eq!(kernel, AttentionKernel::Fused, "{shape:?} runs the CubeCL kernels");
        let (host, host_grads) = run_op(shape, &flex, AttentionKernel::Fused);
        let (device, device_grads) = run_op(shape, &wgpu, kernel);
        let mut worst = vec![("output", close(&device, &host, "output", DEVICE_OP_TOLERANCE))];
        for ((name, d), h) in INPUT_NAMES.iter().zip(&device_grads).zip(&host_grads) {
            worst.push((name, close(d, h, name, DEVICE_OP_TOLERANCE)));
        }
        println!("{shape:?}: worst differences {worst:?}");
    }
    // A head whose neighbourhood outgrows a cube's shared memory (16 x 512 encodings) runs the tensor operations.
    let wide = Tensor::<2>::zeros([1, 512], &wgpu);
    assert_eq!(AttentionKernel::for_queries(&wide, 16, 8), AttentionKernel::TensorOps);
}

/// On a CubeCL device the head runs the device kernels: its displacements and their gradients (of both clouds'
/// points and features) agree with the host kernel's on `flex`.
#[cfg(feature = "wgpu")]
#[test]
fn the_head_agrees_on_wgpu() {
    let config = config(HeadInputs::FeaturesAndOffsets);
    let mut rng = Rng::new(40);
    let (query, target) = (cloud(10, 5, &mut rng), cloud(9, 5, &mut rng));
    let weights = Host::new(10, 3, rng.normals(30, 1.0));
    let run = |device: Device| {
        let head = randomised(&config, 41, &device);
        let leaf = |h: &Host| h.tensor(&device).require_grad();
        let leaves = [leaf(&query.points), leaf(&query.features), leaf(&target.points), leaf(&target.features)];
        let flow = head
            .forward(
                &FrameCloud::new(leaves[0].clone(), leaves[1].clone()),
                &FrameCloud::new(leaves[2].clone(), leaves[3].clone()),
            )
            .unwrap();
        let grads = (flow.clone() * weights.tensor(&device)).sum().backward();
        let mut found = vec![values(flow)];
        found.extend(leaves.iter().map(|t| values(t.grad(&grads).expect("an input gradient"))));
        found
    };
    let flex = run(Device::flex().autodiff());
    let wgpu = run(Device::wgpu(burn::tensor::DeviceKind::default()).autodiff());
    let names = ["displacement", "query points", "query features", "target points", "target features"];
    let worst: Vec<f64> = flex
        .iter()
        .zip(&wgpu)
        .map(|(f, w)| {
            let largest = f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(largest > 0.0);
            f.iter().zip(w).map(|(f, w)| (f - w).abs() / largest).fold(0.0, f64::max)
        })
        .collect();
    println!(
        "worst differences, relative to each tensor's largest entry: {:?}",
        names.iter().zip(&worst).collect::<Vec<_>>()
    );
    let bounds =
        [DISPLACEMENT_TOLERANCE, GRADIENT_TOLERANCE, GRADIENT_TOLERANCE, GRADIENT_TOLERANCE, GRADIENT_TOLERANCE];
    for ((name, worst), bound) in names.iter().zip(&worst).zip(bounds) {
        assert!(*worst <= bound, "{name}: {worst:.2e} of the largest entry, more than {bound:.0e}");
    }
}

/// How closely the head on wgpu follows it on `flex`, relative to each tensor's largest entry: the displacements
/// to float rounding (seen on lavapipe: 4.5e-7); the gradients less closely, as they pass through the slopes of
/// the GELUs and the softmax, which the GPU kernels compute with approximate transcendental functions (seen: at
/// most 8.4e-4, for the query points; the fused op on `flex` matches burn's `flex` gradients to 1e-5).
#[cfg(feature = "wgpu")]
const DISPLACEMENT_TOLERANCE: f64 = 1e-4;
#[cfg(feature = "wgpu")]
const GRADIENT_TOLERANCE: f64 = 5e-3;
