//! The live view of a training run (`dggt train --rerun FILE.rrd` or `--rerun-connect URL`): the destination
//! checked before any work, the recording started once the run is built and finished after it, even when the
//! run fails (what was recorded stays). Builds without the `rerun` feature refuse the flags up front.

use std::path::PathBuf;

use anyhow::{Result, bail};
use dggt_train::{RunOptions, RunSummary, Trainer};

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
    /// The viewer `--rerun FILE` or `--rerun-connect URL` asks for: a file must be new (a recording is never
    /// replaced or appended to), an address must be a rerun proxy URL.
    pub fn from_flags(file: Option<PathBuf>, url: Option<String>) -> Result<Self> {
        match (file, url) {
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
}

#[cfg(feature = "rerun")]
fn run_watched(target: Target, trainer: &mut Trainer, options: RunOptions) -> Result<(RunSummary, Option<String>)> {
    use dggt_rerun::{Destination, TrainingRecording};
    let destination = match target {
        Target::File(path) => Destination::File(path),
        Target::Connect(url) => Destination::Viewer(url),
    };
    let config = trainer.config();
    let mut recording =
        TrainingRecording::start(destination, &trainer.validation_views(), config.viewer.clone(), config.optim.lr)?;
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
