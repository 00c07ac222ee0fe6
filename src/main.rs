//! `dggt`: feedforward 4D reconstruction of dynamic driving scenes — the command-line entry point.

mod backend;

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use dggt_infer::parity::{ParityVectors, run_parity};
use tracing_subscriber::EnvFilter;

use crate::backend::DeviceChoice;

#[derive(Debug, Parser)]
#[command(name = "dggt", version, about = "Feedforward 4D reconstruction of dynamic driving scenes")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Write a procedural driving scene (ray-cast ground truth) in the scene-export layout.
    Synth {
        /// Output folder; must not exist or be empty.
        #[arg(long)]
        out: PathBuf,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        #[arg(long, default_value_t = 20)]
        frames: usize,
        /// 1 = FRONT, 2 adds FRONT_LEFT, 3 adds FRONT_RIGHT.
        #[arg(long, default_value_t = 3)]
        cameras: usize,
        #[arg(long, default_value_t = 160)]
        width: u32,
        #[arg(long, default_value_t = 112)]
        height: u32,
    },
    /// Summarise a driving log: a scene export or a KITTI odometry sequence.
    Inspect {
        /// The scene folder (export layout) or KITTI sequence folder.
        dir: PathBuf,
        /// Only these frame indices, as `START..END` (end exclusive).
        #[arg(long, value_parser = parse_range)]
        frames: Option<std::ops::Range<usize>>,
        /// Only these camera ids (comma separated).
        #[arg(long, value_delimiter = ',')]
        cameras: Option<Vec<usize>>,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Run a folder of reference vectors (config.json, weights, inputs and outputs .safetensors) and compare
    /// every output with the release's; fails when any is out of tolerance.
    Parity {
        /// The vector folder.
        #[arg(long)]
        vectors: PathBuf,
        #[arg(long, value_enum, default_value = "cpu")]
        device: DeviceChoice,
        /// Checkpoint to load [default: DIR/weights.safetensors, else DIR/weights.pt].
        #[arg(long)]
        weights: Option<PathBuf>,
    },
    /// Train (or fine-tune) the network as a TOML configuration describes (`configs/`).
    Train {
        /// The configuration file.
        #[arg(long)]
        config: PathBuf,
        /// Continue from the newest checkpoint in the run's output folder.
        #[arg(long)]
        resume: bool,
        /// Devices to train on, overriding `run.devices` (e.g. `cpu`, `wgpu`, `cuda:0,cuda:1`).
        #[arg(long, value_delimiter = ',')]
        device: Option<Vec<String>>,
        /// Override `run.steps`.
        #[arg(long)]
        steps: Option<u64>,
        /// Override `run.out_dir`.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Build everything and run no step (checks a configuration and its files).
        #[arg(long)]
        dry_run: bool,
    },
    /// Reconstruct a driving scene from unposed images with one forward pass: cameras (JSON, COLMAP,
    /// nerfstudio), depth, dynamic and sky maps, Gaussians as PLY (static, sky, dynamic per time) and renders.
    Reconstruct {
        /// A folder of images (one camera), a folder of per-camera image folders, a glob pattern (quoted:
        /// `'log/*.jpg'` for one camera, `'log/cam*'` for a folder per camera), or a scene export.
        #[arg(long)]
        images: PathBuf,
        /// A trainer checkpoint folder (or run folder), or a release / VGGT `.pt` / `.safetensors` file.
        #[arg(long)]
        checkpoint: PathBuf,
        /// Architecture of a `.pt` / `.safetensors` checkpoint: a model `config.json`, or a training `.toml`
        /// (its model and preprocessing sections).
        #[arg(long, conflicts_with = "preset")]
        config: Option<PathBuf>,
        /// Architecture preset of a `.pt` / `.safetensors` checkpoint: tiny, vggt_1b, dggt [default: dggt].
        #[arg(long)]
        preset: Option<dggt_model::Preset>,
        /// Only these cameras (positions of the per-camera folders, or export camera ids).
        #[arg(long, value_delimiter = ',')]
        cameras: Option<Vec<usize>>,
        /// Only these frames, as `START..END` (end exclusive).
        #[arg(long, value_parser = parse_range)]
        frames: Option<std::ops::Range<usize>>,
        /// Render at these times (seconds since the first chosen frame) [default: the input frames' times].
        #[arg(long, value_delimiter = ',', conflicts_with = "every")]
        times: Option<Vec<f64>>,
        /// Render K evenly spaced times per interval between input frames.
        #[arg(long)]
        every: Option<usize>,
        /// Network input width, a multiple of 14 [default: the --config training file's, else 518].
        #[arg(long)]
        width: Option<u32>,
        /// Frames per chunk of the dense heads (lower uses less memory).
        #[arg(long, default_value_t = 4)]
        chunk: usize,
        /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
        #[arg(long, default_value = "cpu")]
        device: String,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// Drive the pipeline through extreme inputs and report every non-finite value by stage; fails when any
    /// case does.
    Stress {
        /// The larger suite (bigger scenarios, more random extreme mixtures).
        #[arg(long)]
        full: bool,
        /// A folder with `lpips_alex.safetensors` and `vgg16_features.safetensors`: adds LPIPS and Gram terms.
        #[arg(long)]
        loss_weights: Option<PathBuf>,
        /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
        #[arg(long, default_value = "cpu")]
        device: String,
        /// Also write the report as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Evaluate a checkpoint on scene exports under the paper's or the release's protocol: PSNR, SSIM,
    /// LPIPS, aligned depth RMSE and scene-flow metrics per view, split and scene; `eval.json` and `eval.md`.
    Eval(dggt_eval::cli::EvalArgs),
    /// Measure run time against error over the knobs that trade speed for accuracy (input width, input
    /// frames, culling threshold, precision, sky); `bench.csv`, `bench.png` with the Pareto front.
    Bench(dggt_bench::cli::BenchArgs),
    /// List the compute backends of this build and check that each one computes.
    Devices {
        /// Check only this backend.
        #[arg(long, value_enum)]
        device: Option<DeviceChoice>,
    },
}

fn parse_range(text: &str) -> Result<std::ops::Range<usize>, String> {
    let (start, end) = text.split_once("..").ok_or_else(|| format!("expected START..END, got {text:?}"))?;
    let start: usize = start.parse().map_err(|_| format!("bad range start in {text:?}"))?;
    let end: usize = end.parse().map_err(|_| format!("bad range end in {text:?}"))?;
    if end <= start {
        return Err(format!("empty range {text:?}"));
    }
    Ok(start..end)
}

/// `dggt train`: builds the run, trains with a progress bar, prints where the results are.
fn train(
    path: &std::path::Path,
    resume: bool,
    devices: Option<Vec<String>>,
    steps: Option<u64>,
    out: Option<PathBuf>,
    dry_run: bool,
) -> Result<()> {
    let mut config = dggt_train::TrainConfig::load(path)?;
    if let Some(steps) = steps {
        config.run.steps = steps;
    }
    if let Some(out) = out {
        config.run.out_dir = out;
    }
    if let Some(devices) = devices {
        config.run.devices = devices;
    }
    config.validate().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let devices = config.run.devices.iter().map(|d| backend::parse_device(d)).collect::<Result<Vec<_>>>()?;
    let start = if resume { dggt_train::Start::Resume } else { dggt_train::Start::Fresh };
    let mut trainer = dggt_train::Trainer::new(config, devices, start)?;
    let params = burn::module::Module::num_params(trainer.model());
    tracing::info!(
        "{} parameters, starting at step {} of {}",
        params,
        trainer.state().step,
        trainer.config().run.steps
    );
    if dry_run {
        let validation = trainer.validate()?;
        println!(
            "dry run: configuration, scene, network ({params} parameters), losses and optimiser built; validation {}",
            validation.map_or("not configured".into(), |v| format!("PSNR {:.2} dB, SSIM {:.3}", v.psnr, v.ssim))
        );
        return Ok(());
    }
    let summary = trainer.run(dggt_train::RunOptions {
        progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
        stop_after: None,
    })?;
    let out = &trainer.config().run.out_dir;
    print!(
        "trained steps {}..{} in {:.1} s ({} skipped)",
        summary.final_step - summary.steps_run,
        summary.final_step,
        summary.elapsed_s,
        summary.skipped_steps,
    );
    match (summary.first_loss, summary.last_loss) {
        (Some(first), Some(last)) => println!(
            "; loss {first:.4} -> {last:.4}; target PSNR {:.2} -> {:.2} dB",
            summary.first_target_psnr.unwrap_or(f64::NAN),
            summary.last_target_psnr.unwrap_or(f64::NAN),
        ),
        _ => println!("; no full training step in this run (pose warm-up only, or nothing left to run)"),
    }
    if let Some(v) = &summary.validation {
        println!("validation: PSNR {:.2} dB, SSIM {:.4} over {} target views", v.psnr, v.ssim, v.views.len());
    }
    println!("metrics: {}", out.join("metrics.jsonl").display());
    if let Some(dir) = &summary.checkpoint {
        println!("checkpoint: {}", dir.display());
    }
    Ok(())
}

/// `dggt reconstruct`: runs the reconstruction with progress on stderr and prints its summary.
fn reconstruct(options: dggt_reconstruct::ReconstructOptions, device: &str) -> Result<()> {
    let device = backend::parse_device(device)?;
    tracing::info!("reconstructing {} with {} on {device:?}", options.images.display(), options.checkpoint.display());
    let summary = dggt_reconstruct::reconstruct(&options, &device)?;
    println!("{summary}");
    println!("outputs: {} (summary.json)", options.out.display());
    Ok(())
}

/// `dggt parity`: prints the comparison table and a summary line; an error when any output fails.
fn parity(dir: &std::path::Path, device: DeviceChoice, weights: Option<PathBuf>) -> Result<()> {
    let started = std::time::Instant::now();
    let vectors = ParityVectors::open(dir)?;
    let weights = match weights {
        Some(path) => path,
        None => vectors.default_weights()?,
    };
    let device = device.device()?;
    tracing::info!("running {} with {} on {device:?}", dir.display(), weights.display());
    let report = run_parity(&vectors, &weights, &device)
        .with_context(|| format!("running the network of {} with {}", dir.display(), weights.display()))?;
    print!("{report}");
    println!("{} ({:.1} s)", report.summary(), started.elapsed().as_secs_f64());
    let failed: Vec<&str> = report.failed().map(|row| row.name.as_str()).collect();
    anyhow::ensure!(failed.is_empty(), "{} output(s) failed parity: {}", failed.len(), failed.join(", "));
    Ok(())
}

/// `dggt stress`: runs the suite, prints the table; an error when any case fails.
fn stress(full: bool, loss_weights: Option<PathBuf>, device: &str, json: Option<PathBuf>) -> Result<()> {
    let device = backend::parse_device(device)?;
    let started = std::time::Instant::now();
    let options = dggt_stress::StressOptions { full, loss_weights };
    let report = dggt_stress::run_suite(&options, &device).map_err(|e| anyhow::anyhow!("stress suite: {e}"))?;
    print!("{}", report.table());
    println!("({:.1} s on {device:?})", started.elapsed().as_secs_f64());
    if let Some(path) = json {
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let failed: Vec<String> = report.failures().map(|c| format!("{} / {}", c.group, c.name)).collect();
    anyhow::ensure!(failed.is_empty(), "{} stress case(s) failed: {}", failed.len(), failed.join(", "));
    Ok(())
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")))
        .with_writer(std::io::stderr)
        .init();
    match Cli::parse().command {
        Command::Synth { out, seed, frames, cameras, width, height } => {
            let is_non_empty = out.read_dir().map(|mut entries| entries.next().is_some()).unwrap_or(false);
            anyhow::ensure!(!is_non_empty, "{} is not empty; choose a new folder", out.display());
            let config = dggt_synth::SynthConfig { seed, frames, cameras, width, height };
            let started = std::time::Instant::now();
            let summary = dggt_synth::synthesize(&config, &out)
                .with_context(|| format!("writing the synthetic scene to {}", out.display()))?;
            println!(
                "wrote {} images ({} frames x {} cameras at {width}x{height}) and {} instances ({} moving) to {} in {:.1} s",
                summary.images,
                summary.frames,
                summary.cameras,
                summary.instances,
                summary.moving_instances,
                out.display(),
                started.elapsed().as_secs_f64()
            );
        }
        Command::Inspect { dir, frames, cameras, json } => {
            let scene = dggt_data::open_scene(&dir, frames, cameras)
                .with_context(|| format!("reading the log at {}", dir.display()))?;
            let summary = dggt_data::SceneSummary::of(&scene);
            if json {
                println!("{}", serde_json::to_string_pretty(&summary)?);
            } else {
                println!("{summary}");
            }
        }
        Command::Parity { vectors, device, weights } => parity(&vectors, device, weights)?,
        Command::Train { config, resume, device, steps, out, dry_run } => {
            train(&config, resume, device, steps, out, dry_run)?
        }
        Command::Reconstruct {
            images,
            checkpoint,
            config,
            preset,
            cameras,
            frames,
            times,
            every,
            width,
            chunk,
            device,
            out,
        } => {
            let mut options = dggt_reconstruct::ReconstructOptions::new(images, checkpoint, out);
            options.architecture = match (config, preset) {
                (Some(path), _) => Some(dggt_infer::Architecture::Config(path)),
                (None, Some(preset)) => Some(dggt_infer::Architecture::Preset(preset)),
                (None, None) => None,
            };
            options.cameras = cameras;
            options.frames = frames;
            options.times = match (times, every) {
                (Some(times), _) => dggt_reconstruct::TimeRequest::Seconds(times),
                (None, Some(k)) => dggt_reconstruct::TimeRequest::Every(k),
                (None, None) => dggt_reconstruct::TimeRequest::Inputs,
            };
            options.width = width;
            options.chunk_frames = chunk;
            options.progress = std::io::IsTerminal::is_terminal(&std::io::stderr());
            reconstruct(options, &device)?
        }
        Command::Stress { full, loss_weights, device, json } => stress(full, loss_weights, &device, json)?,
        Command::Eval(args) => {
            let device = backend::parse_device(&args.device)?;
            print!("{}", dggt_eval::cli::run(&args, &device)?);
        }
        Command::Bench(args) => {
            let device = backend::parse_device(&args.device)?;
            print!("{}", dggt_bench::cli::run(&args, &device)?);
        }
        Command::Devices { device } => {
            let choices = device.map_or(DeviceChoice::ALL.to_vec(), |d| vec![d]);
            let mut failed = false;
            for choice in choices {
                if !choice.compiled() {
                    println!("{choice:?}: not in this build (cargo feature `{}`)", choice.feature());
                    failed |= device.is_some();
                    continue;
                }
                match choice.device().and_then(|d| backend::self_check(&d).map(|err| (d, err))) {
                    Ok((d, err)) if err < 1e-4 => println!("{choice:?}: ok ({d:?}, matmul error {err:.1e})"),
                    Ok((d, err)) => {
                        println!("{choice:?}: WRONG RESULTS ({d:?}, matmul error {err:.1e})");
                        failed = true;
                    }
                    Err(e) => {
                        println!("{choice:?}: failed: {e:#}");
                        failed = true;
                    }
                }
            }
            anyhow::ensure!(!failed, "a requested backend is unavailable or computes wrong results");
        }
    }
    Ok(())
}
