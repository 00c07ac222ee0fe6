//! The head computes the attention its documentation describes: the displacement against a direct evaluation of
//! the documented formulas (every neighbour token `proj(f_j) + enc_o(o_j)` built, keyed and valued as written),
//! with every target point a neighbour so that the neighbour search plays no part. The head itself evaluates the
//! same attention factored (keys and values of the features projected once per target point, the offset
//! encoding's last layer folded into the key and value matrices); the two agree to f32 rounding.

mod common;

use burn::tensor::activation::softmax;
use burn::tensor::{Device, Int, Tensor, TensorData};
use common::{Host, HostCloud, Rng, randomised, values};
use dggt_flow_head::attention::{self, AttentionKernel, AttentionTensors};
use dggt_flow_head::neighbours::NeighbourSearch;
use dggt_flow_head::scale::ScaleSource;
use dggt_flow_head::{FlowHead, FlowHeadConfig, FlowHeadShape, HeadInputs};

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

/// The documented iteration, written out: `[N, 3]` displacements of `query` towards `target`, every target point
/// attended to by every query.
fn documented_flow(
    head: &FlowHead,
    config: &FlowHeadConfig,
    query_host: &HostCloud,
    target_host: &HostCloud,
) -> Vec<f64> {
    let device = Device::flex();
    let (query, target) = (query_host.upload(&device), target_host.upload(&device));
    let host_targets: Vec<[f32; 3]> =
        values(target.points.clone()).chunks_exact(3).map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect();
    let scale = ScaleSource::of_target(&host_targets, &NeighbourSearch::new(&host_targets))
        .length(&query.points, &target.points);
    let scale = scale.reshape([1, 1]);
    let extent = diagonal(&query_host.points.values, &target_host.points.values);
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
    values(displacement)
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

fn check(inputs: HeadInputs, seed: u64) {
    let device = Device::flex();
    let config = config(inputs);
    let head = randomised(&config, seed, &device);
    let mut rng = Rng::new(seed + 1);
    let (query, target) = (cloud(10, 5, &mut rng), cloud(9, 5, &mut rng));
    let expected = documented_flow(&head, &config, &query, &target);
    let found = values(head.forward(&query.upload(&device), &target.upload(&device)).unwrap());
    let largest = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(largest > 1e-2, "the head moves the points: {largest}");
    for (row, (e, f)) in expected.chunks_exact(3).zip(found.chunks_exact(3)).enumerate() {
        for axis in 0..3 {
            assert!((e[axis] - f[axis]).abs() <= 1e-5 * largest, "query {row} axis {axis}: {} vs {}", f[axis], e[axis]);
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

/// Random inputs of one attention call: 7 queries of 5 neighbours among 6 target points, 2 heads of width 3,
/// encodings of 6 channels.
fn attention_inputs(device: &Device, rng: &mut Rng) -> AttentionTensors {
    let (n, k, targets, heads, width) = (7, 5, 6, 2, 3);
    let hidden = heads * width;
    let rows: Vec<i64> = (0..n * k).map(|_| (rng.unit() * targets as f64) as i64).collect();
    AttentionTensors {
        offsets: leaf([n, k, 3], rng, device),
        rows: Tensor::<2, Int>::from_data(TensorData::new(rows, [n, k]), device),
        keys_values: leaf([targets, 2 * hidden], rng, device),
        encoder_weight: leaf([3, hidden], rng, device),
        encoder_bias: leaf([hidden], rng, device),
        queries: leaf([n, heads, width], rng, device),
        turned: leaf([n, heads, hidden], rng, device),
    }
}

/// The fused host op and the tensor operations (whose gradients `gradients_f64.rs` checks in f64) give the same
/// sums and the same gradients of every float input, on `flex` in f32.
#[test]
fn the_fused_op_matches_the_tensor_operations() {
    let device = Device::flex().autodiff();
    let inputs = attention_inputs(&device, &mut Rng::new(30));
    let [n, heads, width] = inputs.queries.dims();
    let hidden = inputs.turned.dims()[2];
    let probe = Tensor::<1>::from_data(
        TensorData::new(
            Rng::new(31).normals(n * heads * (width + hidden + 3), 1.0),
            [n * heads * (width + hidden + 3)],
        ),
        &device,
    );
    let run = |kernel: AttentionKernel| {
        let out = attention::attend(inputs.clone(), kernel);
        let packed = Tensor::cat(vec![out.values, out.pooled, out.matched], 2).reshape([-1]);
        let grads = (packed.clone() * probe.clone()).sum().backward();
        let gradients = vec![
            values(inputs.offsets.grad(&grads).unwrap()),
            values(inputs.keys_values.grad(&grads).unwrap()),
            values(inputs.encoder_weight.grad(&grads).unwrap()),
            values(inputs.encoder_bias.grad(&grads).unwrap()),
            values(inputs.queries.grad(&grads).unwrap()),
            values(inputs.turned.grad(&grads).unwrap()),
        ];
        (values(packed), gradients)
    };
    let (fused, fused_grads) = run(AttentionKernel::Fused);
    let (tensor, tensor_grads) = run(AttentionKernel::TensorOps);
    close(&fused, &tensor, "output");
    let names = ["offsets", "keys_values", "encoder_weight", "encoder_bias", "queries", "turned"];
    for ((name, f), t) in names.iter().zip(&fused_grads).zip(&tensor_grads) {
        close(f, t, name);
    }
}

/// Entry by entry within 1e-5 of the largest entry.
fn close(found: &[f64], expected: &[f64], what: &str) {
    assert_eq!(found.len(), expected.len(), "{what}");
    let largest = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(largest > 0.0, "{what} is all zero");
    for (i, (f, e)) in found.iter().zip(expected).enumerate() {
        assert!((f - e).abs() <= 1e-5 * largest, "{what}[{i}]: fused {f}, tensor operations {e}");
    }
}

/// On a CubeCL device the head runs the tensor operations: its displacements and their gradients (of both clouds'
/// points and features) agree with the fused op's on `flex`.
#[cfg(feature = "wgpu")]
#[test]
fn the_head_agrees_on_wgpu() {
    use dggt_flow_head::FrameCloud;
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
