//! `dggt bench refiner`: the diffusion refiner's time per frame and the process's peak memory, with made-up
//! weights at sd-turbo's size (or at the sizes of a model folder's configurations).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use burn::tensor::Device;
use dggt_bench::refiner::{RefinerMode, time_refiner_frames};
use dggt_bench::run::median;
use dggt_reconstruct::summary::{peak_memory_mib, resident_memory_mib};
use dggt_refine::random::RefinerConfigs;
use dggt_refine::random::write_random_model;
use dggt_refine::{Latent, Prompt, ReferenceView, Refiner, RefinerPrecision, RefinerSpec};
use dggt_refine_train::fresh::fresh_checkpoint;

use crate::backend::DeviceList;
use crate::commands::output::{self, OutputKind, OverwriteArg};
use crate::commands::refine::load_refiner;

/// Time the diffusion refiner on one frame (made-up weights and frames: the cost, not the quality) and report
/// the process's peak resident memory after building it and after the runs.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Take the network sizes from this model folder's configurations [default: sd-turbo's].
    #[arg(long)]
    model: Option<PathBuf>,
    /// Load the weights of `--model` (and its Difix checkpoint) from disk, as a user's refiner loads, and
    /// report the load's time and peak memory [default: weights made up on the device].
    #[arg(long, requires = "model")]
    load: bool,
    /// Instead of timing: write a model folder of the sizes (sd-turbo's, or `--model`'s) with made-up weights
    /// and a fresh Difix checkpoint (`model_difix.safetensors`) to this folder, for `--model DIR --load`.
    #[arg(long, conflicts_with = "load")]
    write_model: Option<PathBuf>,
    /// With `--write-model`: replace a made-up model folder written earlier there.
    #[command(flatten)]
    overwrite: OverwriteArg,
    #[arg(long, default_value_t = 512)]
    height: usize,
    #[arg(long, default_value_t = 512)]
    width: usize,
    /// With a reference view (two views through the networks).
    #[arg(long)]
    reference_view: bool,
    /// Float types: f32, f16, bf16 (both networks) or f16-unet, bf16-unet (the UNet alone, the VAE in f32).
    #[arg(long, default_value = "f32")]
    precision: RefinerPrecision,
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
pub fn run(args: &Args) -> Result<()> {
    anyhow::ensure!(args.repeat > 0, "--repeat must be at least 1");
    let device = args.device.single()?;
    let (configs, origin) = match &args.model {
        Some(dir) => (RefinerConfigs::read(dir)?, dir.clone()),
        None => (RefinerConfigs::sd_turbo(), PathBuf::from("sd-turbo (built in)")),
    };
    if let Some(dir) = &args.write_model {
        return write_model(&configs, dir, args.overwrite.existing(), &device);
    }
    let started = Instant::now();
    let refiner = build_refiner(args, &configs, &origin, &device)?;
    let build_s = started.elapsed().as_secs_f64();
    let (memory_built, resident_built) = (peak_memory_mib(), resident_memory_mib());
    let mode = if args.reference_view { RefinerMode::ReferenceView } else { RefinerMode::SingleView };
    let size = [args.height, args.width];
    let times = time_refiner_frames(&refiner, size, mode, args.warmup, args.repeat, &device)?;
    let runs: Vec<String> = times.iter().map(|ms| format!("{:.2}", ms / 1e3)).collect();
    let precision = args.precision.name();
    let weights = if args.load { "weights loaded from disk" } else { "made-up weights" };
    println!("refiner: sizes of {}, {weights}, precision {precision}, on {device:?}", origin.display());
    println!("frame: {} x {} ({mode:?})", args.width, args.height);
    let build = if args.load {
        "load (files read, LoRA merged, prompt encoded)"
    } else {
        "build (weights made on the device, prompt encoded)"
    };
    println!("{build}: {build_s:.1} s");
    println!("per frame: median {:.2} s of {} runs [{}]", median(times) / 1e3, runs.len(), runs.join(", "));
    println!("peak memory: {} after building, {} after the runs", mib(memory_built), mib(peak_memory_mib()));
    println!("resident memory: {} after building, {} after the runs", mib(resident_built), mib(resident_memory_mib()));
    Ok(())
}

/// The refiner timed: `--model`'s weights loaded from disk with `--load`, else made-up weights of the sizes.
fn build_refiner(args: &Args, configs: &RefinerConfigs, origin: &Path, device: &Device) -> Result<Refiner> {
    if !args.load {
        return Ok(Refiner::random(configs, origin, device)?.with_precision(args.precision));
    }
    let spec = RefinerSpec {
        model_dir: origin.to_path_buf(),
        checkpoint: origin.join("model_difix.safetensors"),
        prompt: Prompt::Tokens((0..configs.text_encoder.max_position_embeddings as i64).collect()),
        latent: Latent::PosteriorMean,
        reference: ReferenceView::None,
        precision: args.precision,
    };
    load_refiner(&spec, device)
}

/// A made-up model folder; its Difix checkpoint is written last.
const MADE_UP_MODEL: OutputKind =
    OutputKind { command: "bench refiner --write-model", signature: "model_difix.safetensors" };

/// Writes the made-up model folder of `configs` and a fresh Difix checkpoint over it into `dir`.
fn write_model(configs: &RefinerConfigs, dir: &Path, existing: output::Existing, device: &Device) -> Result<()> {
    output::prepare(dir, MADE_UP_MODEL, existing)?;
    let started = Instant::now();
    write_random_model(configs, dir, device)?;
    let checkpoint = dir.join("model_difix.safetensors");
    fresh_checkpoint(dir, 4, 0)?.write_safetensors(&checkpoint)?;
    let bytes: u64 = ["vae/diffusion_pytorch_model", "unet/diffusion_pytorch_model", "text_encoder/model"]
        .iter()
        .filter_map(|stem| std::fs::metadata(dir.join(format!("{stem}.safetensors"))).ok())
        .map(|m| m.len())
        .sum();
    println!(
        "wrote a made-up model folder ({:.2} GiB of f32 weights) and {} in {:.1} s: {}",
        bytes as f64 / f64::from(1u32 << 30),
        checkpoint.display(),
        started.elapsed().as_secs_f64(),
        dir.display()
    );
    Ok(())
}
