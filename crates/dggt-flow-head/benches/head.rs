//! What the flow head costs on the CPU (`flex`, the default thread pool): every pair of adjacent input views of
//! one camera, both ways, as `dggt_scene` runs it.
//!
//! `cargo bench -p dggt-flow-head --bench head`:
//! - **fixture**: 8 input views (the main job's largest draw: 7 pairs, 14 ways) of 300 dynamic pixels each, the
//!   tiny network's feature widths; the forward pass, and forward and backward (a training step's share), for
//!   the default head and the ablation's variants (one iteration; 4 neighbours; offsets only);
//! - **release**: 4 input views of 518 x 350 with a tenth of their pixels dynamic (18 130 each: 3 pairs, 6 ways),
//!   the released network's widths (its DPT maps 256 + 512 + 1024 + 1024 and 128 full-resolution channels); the
//!   forward pass (inference), then forward and backward of one way, with the process's peak resident memory
//!   before and after it (the backward holds what every iteration's attention saved).
//!
//! `cargo bench -p dggt-flow-head --bench head -- CHUNK` runs the release cases alone with queries in chunks of
//! `CHUNK` (the default 8192).
//!
//! The clouds are random points in a 20 m box with standard normal features, and the head's last layer is random
//! (a fresh head's is zero), so every query moves. Medians after a warm-up.

use burn::nn::LinearConfig;
use burn::tensor::{Device, Distribution, Tensor};
use dggt_flow_head::{CloudRole, FlowHead, FlowHeadConfig, FlowHeadShape, FrameCloud, HeadInputs, PreparedCloud};
use dggt_test_data::median_ms;

/// Which passes are timed.
#[derive(Clone, Copy)]
enum Passes {
    Forward,
    ForwardBackward,
}

/// One view's dynamic pixels as a cloud; with `passes` including the backward, its features need a gradient.
fn cloud(points: usize, width: usize, passes: Passes, device: &Device) -> FrameCloud {
    let features = Tensor::random([points, width], Distribution::Normal(0.0, 1.0), device);
    FrameCloud::new(
        Tensor::random([points, 3], Distribution::Uniform(0.0, 20.0), device),
        match passes {
            Passes::Forward => features,
            Passes::ForwardBackward => features.require_grad(),
        },
    )
}

/// A head of `shape` reading `widths`, whose last layer moves the points.
fn moving_head(widths: &[usize], shape: &FlowHeadShape, device: &Device) -> FlowHead {
    let config = FlowHeadConfig { feature_widths: widths.to_vec(), shape: shape.clone() };
    let mut head = config.init(device).expect("a valid configuration");
    head.update.fc2 = LinearConfig::new(config.shape.hidden, 3).init(device);
    head
}

/// The head on `ways` (query, target) of `clouds`, each cloud prepared once as the scene does.
fn run(head: &FlowHead, clouds: &[FrameCloud], ways: &[(usize, usize)], passes: Passes) {
    let prepared: Vec<PreparedCloud> = clouds
        .iter()
        .enumerate()
        .map(|(view, cloud)| head.prepare(cloud, CloudRole::View(view)).expect("valid clouds"))
        .collect();
    let flows: Vec<Tensor<2>> =
        ways.iter().map(|&(q, t)| head.forward_prepared(&prepared[q], &prepared[t]).expect("valid clouds")).collect();
    let total = Tensor::cat(flows, 0).abs().sum();
    match passes {
        Passes::Forward => drop(std::hint::black_box(total.into_scalar::<f32>())),
        Passes::ForwardBackward => drop(std::hint::black_box(total.backward())),
    }
}

/// Both ways of every pair of adjacent views.
fn adjacent_ways(views: usize) -> Vec<(usize, usize)> {
    (1..views).flat_map(|b| [(b - 1, b), (b, b - 1)]).collect()
}

/// One workload: the views' widths, how many, their dynamic pixels, which ways the head runs.
struct Workload<'a> {
    name: &'a str,
    widths: &'a [usize],
    views: usize,
    points: usize,
    ways: Vec<(usize, usize)>,
}

fn measure(workload: &Workload, shape: &FlowHeadShape, passes: Passes) {
    let Workload { name, widths, views, points, ways } = workload;
    let (views, points) = (*views, *points);
    let device = match passes {
        Passes::Forward => Device::flex(),
        Passes::ForwardBackward => Device::flex().autodiff(),
    };
    let head = moving_head(widths, shape, &device);
    let clouds: Vec<FrameCloud> = (0..views).map(|_| cloud(points, widths.iter().sum(), passes, &device)).collect();
    let pass = match passes {
        Passes::Forward => "forward",
        Passes::ForwardBackward => "forward+backward",
    };
    let runs = if points > 1000 { 3 } else { 9 };
    let ms = median_ms(runs, || run(&head, &clouds, ways, passes));
    let variant = match (shape.iterations, shape.neighbours, shape.inputs) {
        _ if shape.chunk != FlowHeadShape::default().chunk => format!(" (chunks of {})", shape.chunk),
        (3, 16, HeadInputs::FeaturesAndOffsets) => String::new(),
        (iterations, 16, HeadInputs::FeaturesAndOffsets) => format!(" ({iterations} iteration(s))"),
        (_, neighbours, HeadInputs::FeaturesAndOffsets) => format!(" ({neighbours} neighbours)"),
        (_, _, HeadInputs::OffsetsOnly) => " (offsets only)".into(),
    };
    println!("{name}/{pass}{variant}: {} ways of {points} queries: {ms:.1} ms", ways.len());
}

/// The process's peak resident memory, in MiB (Linux; `NaN` elsewhere).
fn peak_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap_or("");
    line.split_whitespace().nth(1).and_then(|kb| kb.parse::<f64>().ok()).map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    let chunk = std::env::args().skip(1).find_map(|a| a.parse::<usize>().ok());
    let default = FlowHeadShape::default();
    let release_shape = FlowHeadShape { chunk: chunk.unwrap_or(default.chunk), ..default };
    if chunk.is_none() {
        fixture_cases(&default);
    }
    let release = [256, 512, 1024, 1024, 128];
    let inference = Workload { name: "release", widths: &release, views: 4, points: 18_130, ways: adjacent_ways(4) };
    measure(&inference, &release_shape, Passes::Forward);
    let before = peak_mib();
    let one_way = Workload { views: 2, ways: vec![(0, 1)], ..inference };
    measure(&one_way, &release_shape, Passes::ForwardBackward);
    println!("peak resident memory: {before:.0} MiB before the backward case, {:.0} MiB after", peak_mib());
}

fn fixture_cases(default: &FlowHeadShape) {
    let fixture =
        Workload { name: "fixture", widths: &[16, 32, 64, 64, 16], views: 8, points: 300, ways: adjacent_ways(8) };
    measure(&fixture, default, Passes::Forward);
    for shape in [
        default.clone(),
        FlowHeadShape { iterations: 1, ..default.clone() },
        FlowHeadShape { neighbours: 4, ..default.clone() },
        FlowHeadShape { inputs: HeadInputs::OffsetsOnly, ..default.clone() },
    ] {
        measure(&fixture, &shape, Passes::ForwardBackward);
    }
}
