//! Shared test utilities: a seeded generator, host/tensor conversion, seeded head weights, the clustered clouds of
//! the gradient checks and the central-difference check itself (run in f32 by `gradients.rs`, in f64 by
//! `gradients_f64.rs`).

#![allow(dead_code)]

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::tensor::{Device, Tensor, TensorData};
use dggt_flow_head::{FlowHead, FlowHeadConfig, FlowHeadShape, FrameCloud};

/// A small deterministic generator (splitmix64).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn uniform(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.unit()
    }

    pub fn normal(&mut self) -> f64 {
        let (u, v) = (self.unit().max(1e-300), self.unit());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    pub fn normals(&mut self, n: usize, std: f64) -> Vec<f64> {
        (0..n).map(|_| std * self.normal()).collect()
    }
}

/// A host matrix: rows, columns, values in f64 (converted to the device's float type on upload).
#[derive(Debug, Clone, PartialEq)]
pub struct Host {
    pub rows: usize,
    pub cols: usize,
    pub values: Vec<f64>,
}

impl Host {
    pub fn new(rows: usize, cols: usize, values: Vec<f64>) -> Self {
        assert_eq!(rows * cols, values.len(), "one value per entry of a {rows} x {cols} matrix");
        Self { rows, cols, values }
    }

    pub fn tensor(&self, device: &Device) -> Tensor<2> {
        Tensor::from_data(TensorData::new(self.values.clone(), [self.rows, self.cols]), device)
    }

    pub fn scaled(&self, factor: f64) -> Self {
        Self::new(self.rows, self.cols, self.values.iter().map(|v| v * factor).collect())
    }
}

pub fn values<const D: usize>(tensor: Tensor<D>) -> Vec<f64> {
    tensor.try_into_vec_as::<f64>().unwrap()
}

/// Points and features of one cloud on the host.
#[derive(Debug, Clone)]
pub struct HostCloud {
    pub points: Host,
    pub features: Host,
}

impl HostCloud {
    pub fn upload(&self, device: &Device) -> FrameCloud {
        FrameCloud::new(self.points.tensor(device), self.features.tensor(device))
    }
}

/// Replaces every float parameter by seeded normal values (weights: std `1 / sqrt(fan_in)`, biases: 0.1), the
/// zero-initialised last layer included. Two heads of one configuration mapped with the same seed are equal.
pub struct Randomise(pub Rng);

impl ModuleMapper for Randomise {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let rng = &mut self.0;
        param.map(|old| {
            let shape = old.dims();
            let std = if D == 2 { 1.0 / (shape[0] as f64).sqrt() } else { 0.1 };
            let values = rng.normals(shape.iter().product(), std);
            let trained = old.is_require_grad();
            let new = Tensor::from_data(TensorData::new(values, shape), (&old.device(), old.dtype()));
            if trained { new.require_grad() } else { new }
        })
    }
}

pub fn randomised(config: &FlowHeadConfig, seed: u64, device: &Device) -> FlowHead {
    config.init(device).unwrap().map(&mut Randomise(Rng::new(seed)))
}

/// Adds `delta` to entry `index` of the parameter `id`.
struct Perturb {
    id: ParamId,
    index: usize,
    delta: f64,
}

impl ModuleMapper for Perturb {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        if param.id != self.id {
            return param;
        }
        let (index, delta) = (self.index, self.delta);
        param.map(|old| {
            let mut v = values(old.clone());
            v[index] += delta;
            Tensor::from_data(TensorData::new(v, old.dims()), (&old.device(), old.dtype()))
        })
    }
}

/// Every float parameter: its module path, id and autodiff gradient.
#[derive(Default)]
struct ParamGrads<'a> {
    grads: Option<&'a burn::tensor::Gradients>,
    path: Vec<String>,
    found: Vec<(String, ParamId, Vec<f64>)>,
}

impl ModuleVisitor for ParamGrads<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let grad = param.val().grad(self.grads.unwrap()).map(values).unwrap_or_default();
        self.found.push((self.path.join("."), param.id, grad));
    }
}

/// Every float parameter of `head`: its module path, id and gradient in `grads` (empty when it has none).
pub fn parameter_gradients(head: &FlowHead, grads: &burn::tensor::Gradients) -> Vec<(String, ParamId, Vec<f64>)> {
    let mut visitor = ParamGrads { grads: Some(grads), ..Default::default() };
    head.visit(&mut visitor);
    visitor.found
}

/// The small head of the gradient checks: two feature scales, two heads, four neighbours, two iterations, and
/// chunks of five queries (12 queries: three chunks).
pub fn small_config() -> FlowHeadConfig {
    FlowHeadConfig {
        feature_widths: vec![3, 2],
        shape: FlowHeadShape {
            hidden: 8,
            heads: 2,
            neighbours: 4,
            iterations: 2,
            chunk: 5,
            ..FlowHeadShape::default()
        },
    }
}

/// 12 queries on a lattice 10 units apart, each with a cluster of 4 target points within 0.6 of it: the 4
/// nearest target points of a query moved by less than a few units are its own cluster, so the neighbour sets do
/// not change under a finite-difference step. Features standard normal.
pub fn clustered_clouds(widths: usize, seed: u64) -> (HostCloud, HostCloud) {
    let mut rng = Rng::new(seed);
    let mut query = Vec::new();
    let mut target = Vec::new();
    for i in 0..12 {
        let centre = [(i % 3) as f64 * 10.0, (i / 3 % 2) as f64 * 10.0, (i / 6) as f64 * 10.0];
        query.extend(centre.map(|c| c + rng.uniform(-0.2, 0.2)));
        for _ in 0..4 {
            target.extend(centre.map(|c| c + rng.uniform(-0.6, 0.6)));
        }
    }
    let cloud = |points: Vec<f64>, rng: &mut Rng| {
        let n = points.len() / 3;
        HostCloud { points: Host::new(n, 3, points), features: Host::new(n, widths, rng.normals(n * widths, 1.0)) }
    };
    (cloud(query, &mut rng), cloud(target, &mut rng))
}

/// Steps and error bounds of a central-difference check: an entry passes when
/// `|fd - autodiff| <= of_largest * max |autodiff over the tensor| + relative * |autodiff|`.
#[derive(Debug, Clone, Copy)]
pub struct Tolerance {
    pub step: f64,
    pub of_largest: f64,
    pub relative: f64,
}

/// The gradient check of one head on one pair of clouds, with the loss `sum(F * weights)` for fixed random
/// `weights`.
pub struct GradientCheck {
    pub head: FlowHead,
    pub query: HostCloud,
    pub target: HostCloud,
    pub weights: Host,
    pub device: Device,
    pub tolerance: Tolerance,
}

/// Which input tensor a checked entry belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    QueryPoints,
    QueryFeatures,
    TargetPoints,
    TargetFeatures,
}

pub const INPUTS: [Input; 4] = [Input::QueryPoints, Input::QueryFeatures, Input::TargetPoints, Input::TargetFeatures];

impl GradientCheck {
    fn host_mut<'a>(query: &'a mut HostCloud, target: &'a mut HostCloud, input: Input) -> &'a mut Host {
        match input {
            Input::QueryPoints => &mut query.points,
            Input::QueryFeatures => &mut query.features,
            Input::TargetPoints => &mut target.points,
            Input::TargetFeatures => &mut target.features,
        }
    }

    fn loss(&self, head: &FlowHead, query: &FrameCloud, target: &FrameCloud) -> Tensor<1> {
        (head.forward(query, target).unwrap() * self.weights.tensor(&self.device)).sum()
    }

    /// The head's output on the unperturbed clouds.
    pub fn output(&self) -> Tensor<2> {
        self.head.forward(&self.query.upload(&self.device), &self.target.upload(&self.device)).unwrap()
    }

    fn loss_value(&self, head: &FlowHead, query: &HostCloud, target: &HostCloud) -> f64 {
        values(self.loss(head, &query.upload(&self.device), &target.upload(&self.device)))[0]
    }

    /// Autodiff gradients: of the four inputs (in [`INPUTS`] order) and of every parameter.
    #[allow(clippy::type_complexity)]
    fn autodiff(&self) -> (Vec<Vec<f64>>, Vec<(String, ParamId, Vec<f64>)>) {
        let leaf = |h: &Host| h.tensor(&self.device).require_grad();
        let (query, target) = (self.query.clone(), self.target.clone());
        let tensors = [leaf(&query.points), leaf(&query.features), leaf(&target.points), leaf(&target.features)];
        let query = FrameCloud::new(tensors[0].clone(), tensors[1].clone());
        let target = FrameCloud::new(tensors[2].clone(), tensors[3].clone());
        let grads = self.loss(&self.head, &query, &target).backward();
        let inputs = tensors.iter().map(|t| values(t.grad(&grads).expect("an input gradient"))).collect();
        (inputs, parameter_gradients(&self.head, &grads))
    }

    fn central_difference(&self, evaluate: impl Fn(f64) -> f64) -> f64 {
        let h = self.tolerance.step;
        (evaluate(h) - evaluate(-h)) / (2.0 * h)
    }

    /// Compares `autodiff[i]` with `fd(i)` at `entries`; returns the worst error relative to the largest gradient.
    fn compare(&self, name: &str, autodiff: &[f64], entries: &[usize], fd: impl Fn(usize) -> f64) -> f64 {
        let largest = autodiff.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        assert!(largest > 0.0 && largest.is_finite(), "{name}: gradient {autodiff:?}");
        let Tolerance { of_largest, relative, .. } = self.tolerance;
        let mut worst = 0.0f64;
        for &i in entries {
            let (a, f) = (autodiff[i], fd(i));
            let error = (f - a).abs();
            worst = worst.max(error / largest);
            assert!(
                error <= of_largest * largest + relative * a.abs(),
                "{name}[{i}]: autodiff {a:e} vs finite difference {f:e} (largest entry {largest:e})"
            );
        }
        println!("{name}: {} entries, worst error / largest gradient = {worst:.2e}", entries.len());
        worst
    }

    /// Every entry of the four inputs; returns the worst relative error.
    pub fn check_inputs(&self) -> f64 {
        let (grads, _) = self.autodiff();
        let mut worst = 0.0f64;
        for (input, autodiff) in INPUTS.into_iter().zip(&grads) {
            let entries: Vec<usize> = (0..autodiff.len()).collect();
            let fd = |i: usize| {
                self.central_difference(|delta| {
                    let (mut query, mut target) = (self.query.clone(), self.target.clone());
                    Self::host_mut(&mut query, &mut target, input).values[i] += delta;
                    self.loss_value(&self.head, &query, &target)
                })
            };
            worst = worst.max(self.compare(&format!("{input:?}"), autodiff, &entries, fd));
        }
        worst
    }

    /// Three entries of every parameter (the largest gradient and two seeded others); returns the worst relative
    /// error and the parameters checked.
    pub fn check_parameters(&self, seed: u64) -> (f64, Vec<String>) {
        let (_, params) = self.autodiff();
        let mut rng = Rng::new(seed);
        let mut worst = 0.0f64;
        for (name, id, autodiff) in &params {
            let largest = (0..autodiff.len()).max_by(|&a, &b| autodiff[a].abs().total_cmp(&autodiff[b].abs()));
            let mut entries = vec![largest.unwrap()];
            entries.extend((0..2).map(|_| (rng.next_u64() % autodiff.len() as u64) as usize));
            let fd = |i: usize| {
                self.central_difference(|delta| {
                    let head = self.head.clone().map(&mut Perturb { id: *id, index: i, delta });
                    self.loss_value(&head, &self.query, &self.target)
                })
            };
            worst = worst.max(self.compare(name, autodiff, &entries, fd));
        }
        (worst, params.into_iter().map(|(name, ..)| name).collect())
    }
}

/// The gradient check of [`small_config`] on [`clustered_clouds`], with seeded weights everywhere.
pub fn small_check(device: Device, tolerance: Tolerance) -> GradientCheck {
    let config = small_config();
    let (query, target) = clustered_clouds(config.feature_width(), 3);
    let mut rng = Rng::new(4);
    GradientCheck {
        head: randomised(&config, 5, &device),
        weights: Host::new(query.points.rows, 3, rng.normals(query.points.rows * 3, 1.0)),
        query,
        target,
        device,
        tolerance,
    }
}
