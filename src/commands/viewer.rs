//! The live view of a training run (`dggt train` or `dggt refine-train` with `--rerun FILE.rrd` or
//! `--rerun-connect URL`): the destination checked before any work, the recording started once the run is built
//! and finished after it, even when the run fails (what was recorded stays). Builds without the `rerun` feature
//! refuse the flags up front.

use std::path::PathBuf;

use anyhow::{Result, bail};
use dggt_refine_train::RefineTrainer;
use dggt_refine_train::records::Validation as RefinerValidation;
use dggt_run::progress::Visibility;
use dggt_train::{RunOptions, RunSummary, Trainer};

/// The flags of a run shown live.
#[derive(Debug, Clone, clap::Args)]
pub struct ViewerArgs {
    /// Show the run in rerun as it trains, as a recording written to this new file (`.rrd`, readable while it
    /// grows): the losses per step and pictures at each validation pass (`[viewer]` says what and how often;
    /// builds with the `rerun` feature).
    #[arg(long, value_name = "FILE.rrd", conflicts_with = "rerun_connect")]
    rerun: Option<PathBuf>,
    /// Show the run in a running rerun viewer (`rerun`, of rerun-sdk 0.36.3) at this address, as
    /// `rerun+http://127.0.0.1:9876/proxy`; a viewer that goes away never stops the run.
    #[arg(long, value_name = "URL")]
    rerun_connect: Option<String>,
}

/// A refiner run's held-out scores before and after training, and the recording's line when watched.
pub type RefinerRun = (RefinerValidation, RefinerValidation, Option<String>);

/// Where a run is shown, if anywhere.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Viewer(Option<Target>);

#[derive(Debug, Clone, PartialEq, Eq)]
enum Target {
    /// A new recording file.
    File(PathBuf),
    /// A running viewer's gRPC proxy.
    Connect(String),
}

impl Viewer {
    /// No live view.
    pub fn none() -> Self {
        Self(None)
    }

    /// The viewer `--rerun FILE` or `--rerun-connect URL` asks for: a file must be new (a recording is never
    /// replaced or appended to), an address must be a rerun proxy URL.
    pub fn from_flags(args: ViewerArgs) -> Result<Self> {
        match (args.rerun, args.rerun_connect) {
            (Some(file), _) => {
                check_rerun_build("--rerun")?;
                if file.exists() {
                    bail!(
                        "--rerun {}: the file exists; name a new file (a recording is never replaced)",
                        file.display()
                    );
                }
                Ok(Self(Some(Target::File(file))))
            }
            (None, Some(url)) => {
                check_rerun_build("--rerun-connect")?;
                let scheme = ["rerun://", "rerun+http://", "rerun+https://"].iter().any(|s| url.starts_with(s));
                if !scheme || !url.ends_with("/proxy") {
                    bail!("--rerun-connect {url}: expected a viewer's address as rerun+http://HOST:PORT/proxy");
                }
                Ok(Self(Some(Target::Connect(url))))
            }
            (None, None) => Ok(Self(None)),
        }
    }

    /// Trains `trainer` shown to this viewer; returns the run's summary and, when watched, the recording's line.
    pub fn run(self, trainer: &mut Trainer, options: RunOptions) -> Result<(RunSummary, Option<String>)> {
        match self.0 {
            None => Ok((trainer.run(options)?, None)),
            Some(target) => run_watched(target, trainer, options),
        }
    }

    /// Validates, trains and validates again the refiner run `trainer` shown to this viewer.
    pub fn run_refiner(self, trainer: &mut RefineTrainer, progress: Visibility) -> Result<RefinerRun> {
        match self.0 {
            None => Ok((trainer.validate()?, trainer.run(progress)?, None)),
            Some(target) => run_refiner_watched(target, trainer, progress),
        }
    }
}

#[cfg(feature = "rerun")]
fn destination(target: Target) -> dggt_rerun::Destination {
    match target {
        Target::File(path) => dggt_rerun::Destination::File(path),
        Target::Connect(url) => dggt_rerun::Destination::Viewer(url),
    }
}

#[cfg(feature = "rerun")]
fn run_refiner_watched(target: Target, trainer: &mut RefineTrainer, progress: Visibility) -> Result<RefinerRun> {
    let settings = trainer.config().viewer.clone();
    let pairs = trainer.pairs().held_out_len();
    let mut recording = dggt_rerun::RefinerRecording::start(destination(target), settings, pairs)?;
    let validated = trainer
        .validate_watched(&mut recording)
        .and_then(|before| Ok((before, trainer.run_watched(progress, &mut recording)?)));
    let report = recording.finish();
    let (before, after) = validated?;
    Ok((before, after, Some(report.line())))
}

#[cfg(not(feature = "rerun"))]
fn run_refiner_watched(_: Target, _: &mut RefineTrainer, _: Visibility) -> Result<RefinerRun> {
    Err(without_rerun("--rerun"))
}

#[cfg(feature = "rerun")]
fn run_watched(target: Target, trainer: &mut Trainer, options: RunOptions) -> Result<(RunSummary, Option<String>)> {
    let config = trainer.config();
    let views = trainer.validation_views();
    let mut recording =
        dggt_rerun::TrainingRecording::start(destination(target), &views, config.viewer.clone(), config.optim.lr)?;
    let summary = trainer.run_watched(options, &mut recording);
    let report = recording.finish();
    Ok((summary?, Some(report.line())))
}

#[cfg(not(feature = "rerun"))]
fn run_watched(_: Target, _: &mut Trainer, _: RunOptions) -> Result<(RunSummary, Option<String>)> {
    Err(without_rerun("--rerun"))
}

/// Refuses `flag` in a build without the `rerun` feature, before any work.
pub fn check_rerun_build(flag: &str) -> Result<()> {
    if cfg!(feature = "rerun") { Ok(()) } else { Err(without_rerun(flag)) }
}

fn without_rerun(flag: &str) -> anyhow::Error {
    anyhow::anyhow!("{flag}: this dggt was built without the `rerun` feature (cargo build --release --features rerun)")
}
