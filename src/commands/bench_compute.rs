//! `dggt bench compute`: the arguments of the compute suite, and the run that prints each record as it comes,
//! keeps `compute.json` current, and ends with `compute.md` (the table, with the references' figures beside
//! ours when `--reference` files are given).

use std::path::PathBuf;

use anyhow::{Context, Result};
use dggt_bench::Precision;
use dggt_bench::compute::table::{RecordFile, markdown};
use dggt_bench::compute::{ComputeOptions, IMPLEMENTATION, Record, Scale, Workload, run_compute};

use crate::backend::DeviceList;
use crate::commands::output::{self, OutputKind, OverwriteArg, OverwriteFileArg};

/// Time the network (4 and 12 frames, f32 and bf16), one training step, the rasteriser (2.2M Gaussians into 12
/// views) and find the longest sequence the forward pass fits, at the release's scale (`--scale reduced`: the
/// tiny network at a CPU's scale, the same code).
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    device: DeviceList,
    /// `full` (the release's sizes) or `reduced` (the tiny network, seconds on a CPU).
    #[arg(long, value_enum, default_value = "full")]
    scale: ScaleArg,
    /// Workloads to run: forward, aggregator, train-step, raster, flow-head, longest.
    #[arg(long, value_delimiter = ',', default_value = "forward,aggregator,train-step,raster,flow-head,longest")]
    workloads: Vec<String>,
    /// Precisions of the forward workload.
    #[arg(long, value_delimiter = ',', default_value = "f32,bf16")]
    precisions: Vec<String>,
    /// Precisions of the longest-sequence search.
    #[arg(long, value_delimiter = ',', default_value = "bf16")]
    longest_precisions: Vec<String>,
    /// Seconds each longest-sequence search may take (it reports the best so far when they run out).
    #[arg(long, default_value_t = 240.0)]
    longest_budget_s: f64,
    /// Frame counts of the longest-sequence search: `START..MAX` (doubling from START, never past MAX), or one
    /// count `N` to ask only whether N frames fit. Default: the scale's (16..1024 at full size).
    #[arg(long, value_parser = parse_frame_range)]
    longest_frames: Option<(usize, usize)>,
    /// Timed runs per workload (the median is reported).
    #[arg(long, default_value_t = 5)]
    repeat: usize,
    /// Untimed runs before them (kernel compilation, autotuning).
    #[arg(long, default_value_t = 1)]
    warmup: usize,
    /// Frames per chunk of the dense heads.
    #[arg(long, default_value_t = 4)]
    chunk: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// A reference's record file (`scripts/reference_bench.py --out`); repeatable.
    #[arg(long)]
    reference: Vec<PathBuf>,
    /// Output folder: `compute.json`, `compute.md`, and the training workload's scratch files; must not exist
    /// or be empty.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    overwrite: OverwriteArg,
}

/// A compute suite's folder; `compute.json` is written from the first record on.
const COMPUTE_OUTPUT: OutputKind = OutputKind { command: "bench compute", signature: "compute.json" };

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum ScaleArg {
    Full,
    Reduced,
}

impl Args {
    fn options(&self) -> Result<ComputeOptions> {
        let scale = match self.scale {
            ScaleArg::Full => Scale::Full,
            ScaleArg::Reduced => Scale::Reduced,
        };
        let precisions = |names: &[String]| names.iter().map(|n| Precision::parse(n)).collect::<Result<Vec<_>, _>>();
        Ok(ComputeOptions {
            workloads: self.workloads.iter().map(|w| Workload::parse(w)).collect::<Result<_, _>>()?,
            precisions: precisions(&self.precisions)?,
            longest_precisions: precisions(&self.longest_precisions)?,
            longest_budget_s: self.longest_budget_s,
            longest_range: self.longest_frames,
            repeat: self.repeat,
            warmup: self.warmup,
            chunk_frames: self.chunk,
            seed: self.seed,
            scratch: Some(self.out.join("scratch")),
            ..ComputeOptions::new(scale)
        })
    }
}

/// `START..MAX` or `N` (meaning `N..N`), with `1 <= START <= MAX`.
fn parse_frame_range(text: &str) -> Result<(usize, usize)> {
    let count = |part: &str| {
        part.trim().parse::<usize>().ok().filter(|&n| n > 0).with_context(|| format!("`{part}` is not a frame count"))
    };
    let (start, max) = match text.split_once("..") {
        Some((start, max)) => (count(start)?, count(max)?),
        None => (count(text)?, count(text)?),
    };
    anyhow::ensure!(start <= max, "`{text}`: the search starts past its maximum");
    Ok((start, max))
}

/// How this binary's GPU backends were built, as the records name it.
fn build_flavour() -> &'static str {
    if cfg!(feature = "gpu-tuning") {
        "fusion + autotune"
    } else if cfg!(feature = "gpu-fusion") {
        "fusion, no autotune"
    } else if cfg!(any(feature = "wgpu-backend", feature = "cuda-backend")) {
        "no fusion, no autotune"
    } else {
        "CPU only"
    }
}

pub fn run(args: &Args) -> Result<()> {
    let device = args.device.single()?;
    let options = args.options()?;
    let references = read_all(&args.reference)?;
    let _lock = output::lock(&args.out, "dggt bench compute")?;
    output::prepare(&args.out, COMPUTE_OUTPUT, args.overwrite.existing())?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let json_path = args.out.join("compute.json");
    let mut file = RecordFile {
        implementation: IMPLEMENTATION.into(),
        device: describe(&device),
        build: build_flavour().into(),
        records: vec![],
    };
    eprintln!("dggt bench compute on {} ({:?} scale, {})", file.device, options.scale, file.build);
    let mut save_error = None;
    run_compute(&options, &device, |record: &Record| {
        eprintln!("{}", one_line(record));
        file.records.push(record.clone());
        if let Err(error) = file.write(&json_path) {
            save_error.get_or_insert(error);
        }
    })?;
    if let Some(error) = save_error {
        return Err(error).context("saving compute.json");
    }
    // Written after every record already; once more so that a run of no workloads leaves the file too.
    file.write(&json_path)?;
    let table = markdown(&file, None, &references);
    let table_path = args.out.join("compute.md");
    std::fs::write(&table_path, &table).with_context(|| format!("writing {}", table_path.display()))?;
    print!("{table}");
    println!("outputs: {}, {}", json_path.display(), table_path.display());
    Ok(())
}

/// `dggt bench table`: one table from `compute.json` files of several runs and the references' files.
#[derive(Debug, Clone, clap::Args)]
pub struct TableArgs {
    /// Our record files (`compute.json`), in order: a later record of a key replaces an earlier one.
    #[arg(long, required = true)]
    ours: Vec<PathBuf>,
    /// Our record files of another build to show beside, with our gain over it (e.g. the build without burn's
    /// fusion and autotune, `--features wgpu-backend`); repeatable like `--ours`.
    #[arg(long)]
    baseline: Vec<PathBuf>,
    /// A reference's record file (`scripts/reference_bench.py --out`); repeatable.
    #[arg(long)]
    reference: Vec<PathBuf>,
    /// Where to write the table (it is printed too).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    overwrite: OverwriteFileArg,
}

pub fn run_table(args: &TableArgs) -> Result<()> {
    if let Some(path) = &args.out {
        output::prepare_file(path, "--out", args.overwrite.existing())?;
    }
    let ours = RecordFile::merge(read_all(&args.ours)?)?;
    let baseline = if args.baseline.is_empty() { None } else { Some(RecordFile::merge(read_all(&args.baseline)?)?) };
    let table = markdown(&ours, baseline.as_ref(), &read_all(&args.reference)?);
    if let Some(path) = &args.out {
        std::fs::write(path, &table).with_context(|| format!("writing {}", path.display()))?;
    }
    print!("{table}");
    Ok(())
}

fn read_all(paths: &[PathBuf]) -> Result<Vec<RecordFile>> {
    Ok(paths.iter().map(|path| RecordFile::read(path)).collect::<Result<Vec<_>, _>>()?)
}

/// The device in words: burn's identity of it where the backend gives one (CubeCL backends only).
#[cfg(any(feature = "wgpu-backend", feature = "cuda-backend"))]
fn describe(device: &burn::tensor::Device) -> String {
    match device.identity() {
        Some(identity) => format!("{device:?}: {identity:?}"),
        None => format!("{device:?}"),
    }
}

/// The device in words: a CPU-only build names it.
#[cfg(not(any(feature = "wgpu-backend", feature = "cuda-backend")))]
fn describe(device: &burn::tensor::Device) -> String {
    format!("{device:?}")
}

/// A record as a progress line.
fn one_line(record: &Record) -> String {
    let value = match (&record.error, record.median_ms, record.frames) {
        (Some(error), ..) => format!("failed: {}", error.lines().next().unwrap_or("")),
        (None, Some(ms), _) => format!("{ms:.1} ms (median of {})", record.runs_ms.len()),
        (None, None, Some(frames)) => format!("{frames} frames"),
        (None, None, None) => "no figure".into(),
    };
    let memory = record.peak_mib.map_or(String::new(), |m| format!(", {m:.0} MiB held"));
    let first = record.first_run_ms.map_or(String::new(), |ms| format!(", first run {:.1} s", ms / 1e3));
    format!("  {:<34} {value}{memory}{first}", record.key)
}
