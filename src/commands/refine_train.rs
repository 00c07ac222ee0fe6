//! `dggt refine-train`: trains the diffusion refiner as a TOML configuration describes
//! (`configs/refine-tiny.toml`), with progress, checkpoints and resume, and writes the trained refiner where
//! the refiner's loader reads it (`dggt_refine_train::difix_checkpoint::load_trained_refiner`).

use std::path::PathBuf;

use anyhow::Result;
use dggt_refine_train::{RefineTrainConfig, RefineTrainError, RefineTrainer};
use dggt_run::Start;
use dggt_run::progress::Visibility;

use crate::backend::DeviceSpec;
use crate::commands::output::{self, OverwriteFileArg};
use crate::commands::{train, viewer};

/// Train the single-step diffusion refiner (Difix) on pairs of frames with artifacts and their ground truth.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The configuration file.
    #[arg(long)]
    config: PathBuf,
    /// Continue from the newest checkpoint in the run's output folder. Without it, a folder that already holds
    /// a run (checkpoints, metrics) is refused.
    #[arg(long)]
    resume: bool,
    /// The device to train on (`cpu`, `wgpu`, `cuda:0`).
    #[arg(long, default_value = "cpu")]
    device: DeviceSpec,
    /// Override `run.steps` (at least 1).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    steps: Option<u64>,
    /// Override `run.out_dir`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Where to write the trained refiner (default `OUT/refiner.safetensors`, the run's own file).
    #[arg(long)]
    export: Option<PathBuf>,
    /// Replace an existing `--export` file.
    #[command(flatten)]
    overwrite: OverwriteFileArg,
    /// The run shown live in rerun: at each validation pass held-out renders before and after refining.
    #[command(flatten)]
    viewer: viewer::ViewerArgs,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(export) = &args.export {
        output::prepare_file(export, "--export", args.overwrite.existing())?;
    }
    let mut config = RefineTrainConfig::load(&args.config)?;
    if let Some(steps) = args.steps {
        config.run.steps = steps;
    }
    if let Some(out) = args.out {
        config.run.out_dir = out;
    }
    config.validate().map_err(|e| anyhow::anyhow!("{}: {e}", args.config.display()))?;
    let viewer = viewer::Viewer::from_flags(args.viewer)?;
    let start = if args.resume { Start::Resume } else { Start::Fresh };
    let _lock = output::lock(&config.run.out_dir, "dggt refine-train")?;
    let mut trainer = RefineTrainer::new(config, args.device.device()?, start).map_err(|error| match error {
        RefineTrainError::Run(error) => train::run_with_flags(error),
        other => other.into(),
    })?;
    let first_step = trainer.state().step;
    let (before, after, recording) = viewer.run_refiner(&mut trainer, Visibility::on_terminal())?;
    let out = trainer.config().run.out_dir.clone();
    let export = args.export.unwrap_or_else(|| out.join("refiner.safetensors"));
    trainer.write_difix_checkpoint(&export)?;
    println!(
        "trained steps {first_step}..{} ({} skipped); held-out PSNR {:.2} -> {:.2} dB (renders as they are: {:.2} dB)",
        trainer.state().step,
        trainer.state().skipped_steps,
        before.refined_psnr,
        after.refined_psnr,
        after.render_psnr
    );
    println!("metrics: {}", out.join("metrics.jsonl").display());
    println!("refiner: {}", export.display());
    if let Some(recording) = recording {
        println!("{recording}");
    }
    Ok(())
}
