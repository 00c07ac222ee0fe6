//! `dggt train`: a run as a TOML configuration describes it, with progress, and where its results are.

use std::path::{Path, PathBuf};

use anyhow::Result;
use dggt_bench::curves::{RunCurves, default_label, draw_curves};
use dggt_run::RunError;
use dggt_run::progress::Visibility;
use dggt_run::run_folder::METRICS;
use dggt_train::resume::AllowedChanges;
use dggt_train::{ProcessGroup, RunOptions, Start, TrainConfig, TrainError, Trainer};

use crate::backend::DeviceList;
use crate::commands::{output, viewer};

/// Train (or fine-tune) the network as a TOML configuration describes (`configs/`).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The configuration file.
    #[arg(long)]
    config: PathBuf,
    /// Continue from the newest checkpoint in the run's output folder. Without it, a folder that already holds
    /// a run (checkpoints, metrics, validation renders) is refused.
    #[arg(long)]
    resume: bool,
    /// Devices to train on, overriding `run.devices` (e.g. `cpu`, `wgpu`, `cuda:0,cuda:1`).
    #[arg(long)]
    device: Option<DeviceList>,
    /// Override `run.steps` (at least 1).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    steps: Option<u64>,
    /// Override `run.out_dir`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Build everything and run no step (checks a configuration and its files).
    #[arg(long)]
    dry_run: bool,
    /// With --resume: continue although this setting of what the network sees changed since the checkpoint
    /// (`data.preprocess.target_width`, `sampler.max_inputs`, ..., or a whole section: `data.preprocess`,
    /// `sampler`); repeatable. Without it such a change is refused.
    #[arg(long, value_name = "KEY", requires = "resume")]
    allow_changed: Vec<String>,
    /// The run shown live in rerun: at each validation pass the renders beside the truth, depth, dynamic
    /// masks, cameras and Gaussians.
    #[command(flatten)]
    viewer: viewer::ViewerArgs,
}

/// The training curves `dggt train` draws into its run folder at the end of a run.
const CURVES_FILE: &str = "curves.png";

/// Builds the run, trains with a progress bar, prints where the results are.
pub fn run(args: Args) -> Result<()> {
    let path = &args.config;
    let mut config = TrainConfig::load(path)?;
    if let Some(steps) = args.steps {
        config.run.steps = steps;
    }
    if let Some(out) = args.out {
        config.run.out_dir = out;
    }
    config.validate().map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    let devices = match args.device {
        Some(list) => list,
        None => DeviceList::from_names(&config.run.devices)
            .map_err(|e| anyhow::anyhow!("{}: run.devices: {e}", path.display()))?,
    };
    let start = if args.resume { Start::Resume } else { Start::Fresh };
    // One process, or one rank of `mpirun -np P dggt train` (docs/DISTRIBUTED.md).
    let group = ProcessGroup::from_environment()?;
    if group.size() > 1 {
        tracing::info!(rank = group.rank(), ranks = group.size(), "training as one rank of an MPI job");
    }
    // The writing rank owns the run folder and the live view; the other ranks only read the checkpoint it names.
    let viewer = match group.is_writer() {
        true => viewer::Viewer::from_flags(args.viewer)?,
        false => viewer::Viewer::none(),
    };
    let _lock = group.is_writer().then(|| output::lock(&config.run.out_dir, "dggt train")).transpose()?;
    let allowed = AllowedChanges::keys(args.allow_changed);
    let mut trainer = Trainer::in_group(config, devices.devices()?, start, group, &allowed).map_err(with_flags)?;
    let params = burn::module::Module::num_params(trainer.model());
    tracing::info!(
        "{} parameters, starting at step {} of {}",
        params,
        trainer.state().step,
        trainer.config().run.steps
    );
    if args.dry_run {
        if !trainer.group().is_writer() {
            return Ok(());
        }
        let validation = trainer.validate()?;
        println!(
            "dry run: configuration, scene, network ({params} parameters), losses and optimiser built; validation {}",
            validation.map_or("not configured".into(), |v| v.scores_line())
        );
        return Ok(());
    }
    let options = RunOptions { progress: Visibility::on_terminal(), stop_after: None };
    let (summary, recording) = viewer.run(&mut trainer, options)?;
    if !trainer.group().is_writer() {
        return Ok(());
    }
    let out = &trainer.config().run.out_dir;
    let curves = draw_run_curves(out);
    let spikes = match trainer.state().spike_skipped_steps {
        0 => String::new(),
        n => format!(", {n} loss spikes skipped"),
    };
    print!(
        "trained steps {}..{} in {:.1} s ({} skipped{spikes})",
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
        println!("validation: {} over {} target views", v.scores_line(), v.views.len());
        if v.scenes.len() > 1 {
            for scene in &v.scenes {
                println!("  {:<32} {}", scene.scene, scene.scores_line());
            }
        }
    }
    let index = trainer.index();
    if !index.excluded.is_empty() || trainer.state().bad_samples > 0 {
        println!(
            "data: {} scenes excluded at indexing (see {}), {} samples failed to load and were replaced",
            index.excluded.len(),
            out.join("scene-index.json").display(),
            trainer.state().bad_samples
        );
    }
    println!("metrics: {}", out.join(METRICS).display());
    if let Some(png) = curves {
        println!("curves: {}", png.display());
    }
    if let Some(dir) = &summary.checkpoint {
        println!("checkpoint: {}", dir.display());
    }
    if let Some(recording) = recording {
        println!("{recording}");
    }
    Ok(())
}

/// Draws the run's training curves (all of its metrics, a resumed run's earlier steps included) into its
/// folder; returns the file. A failure to draw them is a warning: the run's results stand without them.
fn draw_run_curves(out: &Path) -> Option<PathBuf> {
    let png = out.join(CURVES_FILE);
    let drawn = RunCurves::read(&out.join(METRICS), default_label(out)).and_then(|run| draw_curves(&[run], &png));
    match drawn {
        Ok(()) => Some(png),
        Err(error) => {
            tracing::warn!("training curves not drawn: {error}");
            None
        }
    }
}

/// A refusal to start a run, with the flags that resolve it; other errors as they are.
pub fn with_flags(error: TrainError) -> anyhow::Error {
    match error {
        TrainError::Run(error) => run_with_flags(error),
        TrainError::ArchitectureChanged { .. } => anyhow::anyhow!("{error} (--out DIR)"),
        other => other.into(),
    }
}

/// A refusal of the run's machinery to start a run (of `train` or `refine-train`) over another run's files,
/// with the flags that resolve it; other errors as they are.
pub fn run_with_flags(error: RunError) -> anyhow::Error {
    match error {
        RunError::RunExists { .. } => {
            anyhow::anyhow!("{error}: continue it with --resume, or train into another folder with --out DIR")
        }
        other => other.into(),
    }
}
