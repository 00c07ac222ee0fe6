//! `dggt bench compute`: the network, a training step and the rasteriser at the release's scale, timed on one
//! device, with the memory the device's allocator holds: the numbers a user compares against the release.
//!
//! Workloads ([`Workload`]), each a list of [`Record`]s keyed the way `scripts/reference_bench.py` keys the
//! same work on the release and gsplat, so that [`table`] can print the ratios:
//!
//! - `forward/{S}/{precision}`: the network on `S` frames ([`forward`]);
//! - `train-step/{N}+{2N}/f32`: one optimiser step of the release's fine-tuning recipe ([`training`]);
//! - `raster/{G}x{V}/forward` and `.../forward+backward`: the rasteriser alone ([`raster`]);
//! - `flow-head/{V}x{Q}/forward` and `.../forward+backward`: the learnt scene-flow head alone ([`flow_head`]);
//! - `aggregator/{S}/{precision}`: the aggregator alone, to tell the backbone from the heads ([`forward`]);
//! - `longest/{precision}`: the most frames the forward pass fits in the device's memory ([`forward`]).
//!
//! [`Scale::Full`] is the release's: the 1.35B network on 518x350 frames, 2.2M Gaussians into 12 views.
//! [`Scale::Reduced`] runs the same code on the tiny network at a size a CPU finishes in seconds, so that the
//! suite is tested without a GPU.

mod flow_head;
mod forward;
mod memory;
mod raster;
pub mod table;
mod training;

use std::path::PathBuf;
use std::time::Instant;

use burn::tensor::Device;
use dggt_geom::ImageSize;
use dggt_model::ModelConfig;
use serde::{Deserialize, Serialize};

use crate::error::BenchError;
use crate::knobs::Precision;
use crate::run::median;

pub use memory::DeviceMemory;

/// The sizes the suite runs at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// The release's: the DGGT network (1.35B parameters), 518x350 frames, 2.2M Gaussians x 12 views.
    Full,
    /// The tiny network on 70x56 frames, 20k Gaussians x 2 views: the same code in seconds on a CPU.
    Reduced,
}

/// What one scale means in numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct ScaleSpec {
    pub model: ModelConfig,
    /// The network's input (and every rendered view's) size.
    pub image: ImageSize,
    /// Frame counts of the forward workload.
    pub forward_frames: Vec<usize>,
    /// Input frames `N` of the training step (it renders `2N` targets).
    pub train_inputs: usize,
    pub raster_gaussians: usize,
    pub raster_views: usize,
    /// Input views of the flow-head workload and dynamic pixels (queries) of each.
    pub flow_views: usize,
    pub flow_queries: usize,
    /// Frame counts the longest-sequence search starts from and never passes.
    pub longest_start: usize,
    pub longest_max: usize,
}

impl Scale {
    pub fn spec(self) -> ScaleSpec {
        match self {
            Self::Full => ScaleSpec {
                model: ModelConfig::dggt(),
                image: ImageSize::new(518, 350).expect("a valid size"),
                forward_frames: vec![4, 12],
                train_inputs: 4,
                raster_gaussians: 2_200_000,
                raster_views: 12,
                // Four frames of 518x350 with a tenth of their pixels dynamic.
                flow_views: 4,
                flow_queries: 18_130,
                longest_start: 16,
                longest_max: 1024,
            },
            Self::Reduced => ScaleSpec {
                model: ModelConfig::tiny(),
                image: ImageSize::new(70, 56).expect("a valid size"),
                forward_frames: vec![2, 4],
                train_inputs: 2,
                raster_gaussians: 20_000,
                raster_views: 2,
                flow_views: 3,
                flow_queries: 300,
                longest_start: 2,
                longest_max: 8,
            },
        }
    }
}

/// The suite's workloads, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Workload {
    Forward,
    Aggregator,
    TrainStep,
    Raster,
    FlowHead,
    Longest,
}

impl Workload {
    pub const ALL: [Workload; 6] =
        [Self::Forward, Self::Aggregator, Self::TrainStep, Self::Raster, Self::FlowHead, Self::Longest];

    pub fn name(self) -> &'static str {
        match self {
            Self::Forward => "forward",
            Self::Aggregator => "aggregator",
            Self::TrainStep => "train-step",
            Self::Raster => "raster",
            Self::FlowHead => "flow-head",
            Self::Longest => "longest",
        }
    }

    pub fn parse(text: &str) -> Result<Self, BenchError> {
        Self::ALL.into_iter().find(|w| w.name() == text.trim()).ok_or_else(|| {
            BenchError::setting(
                "workload",
                format!("`{text}`: expected forward, aggregator, train-step, raster, flow-head or longest"),
            )
        })
    }
}

/// Everything the suite is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct ComputeOptions {
    pub scale: Scale,
    pub workloads: Vec<Workload>,
    /// Precisions of the forward workload (an unsupported one is recorded as an error).
    pub precisions: Vec<Precision>,
    /// Precisions the longest-sequence search runs in.
    pub longest_precisions: Vec<Precision>,
    /// Wall-clock budget of each longest-sequence search (it records the best so far when it runs out).
    pub longest_budget_s: f64,
    /// Frame counts the longest-sequence search starts from and never passes (the scale's when `None`):
    /// `Some((150, 150))` asks only whether 150 frames fit.
    pub longest_range: Option<(usize, usize)>,
    pub repeat: usize,
    pub warmup: usize,
    /// Frames per chunk of the dense heads.
    pub chunk_frames: usize,
    pub seed: u64,
    /// Where the training workload writes its synthetic scene and run folder (a temporary folder when `None`).
    pub scratch: Option<PathBuf>,
}

impl ComputeOptions {
    pub fn new(scale: Scale) -> Self {
        Self {
            scale,
            workloads: Workload::ALL.to_vec(),
            precisions: vec![Precision::F32, Precision::Bf16],
            longest_precisions: vec![Precision::Bf16],
            longest_budget_s: 240.0,
            longest_range: None,
            repeat: 5,
            warmup: 1,
            chunk_frames: 4,
            seed: 0,
            scratch: None,
        }
    }
}

/// One measured piece of work (the layout `scripts/reference_bench.py` writes too).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// What was run, e.g. `forward/4/bf16`; equal keys are the same work.
    pub key: String,
    /// Which implementation ran it (`dggt-rs`, `release`, `gsplat`, ...).
    #[serde(rename = "impl")]
    pub implementation: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub median_ms: Option<f64>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub runs_ms: Vec<f64>,
    /// The first (untimed) run: it compiles the kernels and, in a build with autotune, tunes them for these
    /// shapes, so it is what a user waits for once per machine and shape (later runs read the kept results).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_run_ms: Option<f64>,
    /// Device memory the allocator held at the end of the work (after a clean-up at its start), MiB.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_mib: Option<f64>,
    /// The longest-sequence search's answer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<usize>,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// This implementation's name in the records.
pub const IMPLEMENTATION: &str = "dggt-rs";

impl Record {
    fn new(key: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            implementation: IMPLEMENTATION.into(),
            median_ms: None,
            runs_ms: Vec::new(),
            first_run_ms: None,
            peak_mib: None,
            frames: None,
            note: String::new(),
            error: None,
        }
    }

    // Takes any error by value, like `impl Into<String>`, so `Err(e) => Record::failed(key, e)` reads plainly.
    #[allow(clippy::needless_pass_by_value)]
    fn failed(key: impl Into<String>, error: impl ToString) -> Self {
        Self { error: Some(error.to_string()), ..Self::new(key) }
    }

    fn with_note(mut self, note: impl Into<String>) -> Self {
        self.note = note.into();
        self
    }
}

/// Runs every requested workload on `device`, handing each record to `on_record` as soon as it is measured
/// (so that a long run can save what it has), and returns them all. A workload that fails is recorded with its
/// error and the suite goes on.
pub fn run_compute(
    options: &ComputeOptions,
    device: &Device,
    mut on_record: impl FnMut(&Record),
) -> Result<Vec<Record>, BenchError> {
    let spec = options.scale.spec();
    let mut records = Vec::new();
    let mut keep = |record: Record| {
        on_record(&record);
        records.push(record);
    };
    let mut workloads = options.workloads.clone();
    workloads.sort();
    workloads.dedup();
    for workload in workloads {
        match workload {
            Workload::Forward => forward::forward_records(options, &spec, device, &mut keep)?,
            Workload::Aggregator => forward::aggregator_records(options, &spec, device, &mut keep)?,
            Workload::TrainStep => keep(training::train_step_record(options, &spec, device)),
            Workload::Raster => raster::raster_records(options, &spec, device, &mut keep),
            Workload::FlowHead => flow_head::flow_head_records(options, &spec, device, &mut keep)?,
            Workload::Longest => forward::longest_records(options, &spec, device, &mut keep)?,
        }
    }
    Ok(records)
}

/// Which passes a record of the rasteriser or the flow head times (part of its key).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Passes {
    Forward,
    ForwardBackward,
}

impl Passes {
    fn name(self) -> &'static str {
        match self {
            Self::Forward => "forward",
            Self::ForwardBackward => "forward+backward",
        }
    }
}

/// Times `work` `repeat` times after `warmup` untimed runs; the record has every run and their median, and the
/// device memory held at the end. `work` must block until its results are computed.
fn timed(
    key: String,
    options: &ComputeOptions,
    device: &Device,
    mut work: impl FnMut() -> Result<(), BenchError>,
) -> Record {
    let memory = DeviceMemory::start(device);
    let mut runs_ms = Vec::with_capacity(options.repeat);
    let mut first_run_ms = None;
    for run in 0..options.warmup + options.repeat.max(1) {
        if run < options.warmup {
            tracing::info!("{key}: untimed run {} of {} (compiles and tunes kernels)", run + 1, options.warmup);
        }
        let started = Instant::now();
        if let Err(error) = memory::guarded(&mut work) {
            return Record { first_run_ms, ..Record::failed(key, error) };
        }
        let elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
        first_run_ms.get_or_insert(elapsed_ms);
        if run >= options.warmup {
            runs_ms.push(elapsed_ms);
        }
    }
    Record {
        median_ms: Some(median(runs_ms.clone())),
        runs_ms,
        first_run_ms,
        peak_mib: memory.held_mib(),
        ..Record::new(key)
    }
}
