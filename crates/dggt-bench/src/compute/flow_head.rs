//! The learnt scene-flow head alone: `V` input views of `Q` dynamic pixels each, every pair of adjacent views
//! both ways (as `dggt_scene` runs it, each view's cloud prepared once), forward, and forward then backward (the
//! loss is the sum of the displacements' magnitudes; gradients for every cloud's points and features and for the
//! head's parameters). On `flex` and the CubeCL devices the attention runs the fused op, elsewhere burn's tensor
//! operations (`dggt_flow_head::attention`).
//!
//! The clouds: points uniform in a 20 m box, features uniform in `[-1, 1]`, widths the network's (the DPT maps'
//! and the full-resolution features'), SplitMix64 draws. The head has the default shape with a random last layer
//! (a fresh head's is zero), so that every query moves and every iteration searches new neighbours.

use burn::nn::LinearConfig;
use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::random::SplitMix64;
use dggt_flow_head::{CloudRole, FlowHead, FlowHeadConfig, FlowHeadShape, FrameCloud, PreparedCloud};

use super::{ComputeOptions, Passes, Record, ScaleSpec, timed};
use crate::error::BenchError;
use crate::stages::settle;

/// `flow-head/{V}x{Q}/forward` and `flow-head/{V}x{Q}/forward+backward`.
pub fn flow_head_records(
    options: &ComputeOptions,
    spec: &ScaleSpec,
    device: &Device,
    keep: &mut impl FnMut(Record),
) -> Result<(), BenchError> {
    let (views, queries) = (spec.flow_views, spec.flow_queries);
    let widths = spec.model.flow_features();
    let ways: Vec<(usize, usize)> = (1..views).flat_map(|b| [(b - 1, b), (b, b - 1)]).collect();
    for passes in [Passes::Forward, Passes::ForwardBackward] {
        let key = format!("flow-head/{views}x{queries}/{}", passes.name());
        let device = match passes {
            Passes::Forward => device.clone(),
            Passes::ForwardBackward => device.clone().autodiff(),
        };
        let head = moving_head(&widths, &device)?;
        let mut random = SplitMix64::new(options.seed);
        let clouds: Vec<FrameCloud> =
            (0..views).map(|_| cloud(queries, widths.iter().sum(), passes, &mut random, &device)).collect();
        let record = timed(key, options, &device, || run(&head, &clouds, &ways, passes));
        let note = format!("{} ways of {queries} queries, feature widths {widths:?}, default head", ways.len());
        keep(record.with_note(note));
    }
    Ok(())
}

/// The default head reading `widths`, its last layer re-initialised at random.
fn moving_head(widths: &[usize], device: &Device) -> Result<FlowHead, BenchError> {
    let config = FlowHeadConfig { feature_widths: widths.to_vec(), shape: FlowHeadShape::default() };
    let mut head = config.init(device).map_err(|error| BenchError::setting("flow head", error.to_string()))?;
    head.update.fc2 = LinearConfig::new(config.shape.hidden, 3).init(device);
    Ok(head)
}

/// One view's cloud; with `passes` including the backward, its points and features need gradients.
fn cloud(points: usize, width: usize, passes: Passes, random: &mut SplitMix64, device: &Device) -> FrameCloud {
    let mut draw = |len: usize, low: f32, high: f32| -> Vec<f32> {
        (0..len).map(|_| low + (high - low) * random.unit()).collect()
    };
    let positions = Tensor::<2>::from_data(TensorData::new(draw(3 * points, 0.0, 20.0), [points, 3]), device);
    let features = Tensor::<2>::from_data(TensorData::new(draw(points * width, -1.0, 1.0), [points, width]), device);
    match passes {
        Passes::ForwardBackward => FrameCloud::new(positions.require_grad(), features.require_grad()),
        Passes::Forward => FrameCloud::new(positions, features),
    }
}

fn run(head: &FlowHead, clouds: &[FrameCloud], ways: &[(usize, usize)], passes: Passes) -> Result<(), BenchError> {
    let prepared: Vec<PreparedCloud> = clouds
        .iter()
        .enumerate()
        .map(|(view, cloud)| head.prepare(cloud, CloudRole::View(view)))
        .collect::<Result<_, _>>()?;
    let flows: Vec<Tensor<2>> =
        ways.iter().map(|&(q, t)| head.forward_prepared(&prepared[q], &prepared[t])).collect::<Result<_, _>>()?;
    let loss = Tensor::cat(flows, 0).abs().sum();
    match passes {
        Passes::Forward => settle(&loss),
        Passes::ForwardBackward => {
            let grads = loss.backward();
            let total = clouds
                .iter()
                .filter_map(|cloud| cloud.features.grad(&grads).map(|g| g.sum()))
                .reduce(|a, b| a + b)
                .ok_or(BenchError::Missing("flow head: the features' gradients are missing"))?;
            settle(&total)
        }
    }
}
