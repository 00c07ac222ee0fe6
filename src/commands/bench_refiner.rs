//! `dggt bench refiner`: the diffusion refiner's time per frame and the process's peak memory, with made-up
//! weights at sd-turbo's size (or at the sizes of a model folder's configurations).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use dggt_bench::Precision;
use dggt_bench::refiner::{RefinerMode, time_refiner_frames};
use dggt_bench::run::median;
use dggt_reconstruct::summary::peak_memory_mib;
use dggt_refine::Refiner;
use dggt_refine::random::RefinerConfigs;

use crate::backend::DeviceList;

/// Time the diffusion refiner on one frame (made-up weights and frames: the cost, not the quality) and report
/// the process's peak resident memory after building it and after the runs.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Take the network sizes from this model folder's configurations [default: sd-turbo's].
    #[arg(long)]
    model: Option<PathBuf>,
    #[arg(long, default_value_t = 512)]
    height: usize,
    #[arg(long, default_value_t = 512)]
    width: usize,
    /// With a reference view (two views through the networks).
    #[arg(long)]
    reference_view: bool,
    /// The UNet's float type: f32, f16 or bf16 (the VAE stays f32).
    #[arg(long, default_value = "f32")]
    unet_precision: String,
    /// Timed runs (the median is reported).
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Untimed runs before them.
    #[arg(long, default_value_t = 0)]
    warmup: usize,
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    device: DeviceList,
}

fn mib(value: Option<f64>) -> String {
    value.map_or_else(|| "unknown".into(), |v| format!("{v:.0} MiB"))
}

/// Builds the refiner, times it and prints one line per figure.
pub fn run(args: Args) -> Result<()> {
    anyhow::ensure!(args.repeat > 0, "--repeat must be at least 1");
    let device = args.device.single()?;
    let precision = Precision::parse(&args.unet_precision)?;
    let (configs, origin) = match &args.model {
        Some(dir) => (RefinerConfigs::read(dir)?, dir.clone()),
        None => (RefinerConfigs::sd_turbo(), PathBuf::from("sd-turbo (built in)")),
    };
    let started = Instant::now();
    let refiner = Refiner::random(&configs, Path::new(&origin), &device)?.with_unet_dtype(precision.dtype());
    let build_s = started.elapsed().as_secs_f64();
    let memory_built = peak_memory_mib();
    let mode = if args.reference_view { RefinerMode::ReferenceView } else { RefinerMode::SingleView };
    let size = [args.height, args.width];
    let times = time_refiner_frames(&refiner, size, mode, args.warmup, args.repeat, &device)?;
    let runs: Vec<String> = times.iter().map(|ms| format!("{:.2}", ms / 1e3)).collect();
    println!("refiner: sizes of {}, made-up weights, UNet in {precision}, on {device:?}", origin.display());
    println!("frame: {} x {} ({mode:?})", args.width, args.height);
    println!("build (weights made on the device, prompt encoded): {build_s:.1} s");
    println!("per frame: median {:.2} s of {} runs [{}]", median(times) / 1e3, runs.len(), runs.join(", "));
    println!("peak memory: {} after building, {} after the runs", mib(memory_built), mib(peak_memory_mib()));
    Ok(())
}
