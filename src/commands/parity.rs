//! `dggt parity`: a folder of the release's reference vectors run and compared output by output. A folder of
//! the refiner's vectors (`base/`, `model_difix.pkl`, inputs and outputs) runs the refiner instead.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use dggt_parity::network::run_parity;
use dggt_parity::refiner::is_refiner_folder;
use dggt_parity::{ParityReport, ParityVectors};

use crate::backend::DeviceList;

/// Run a folder of reference vectors (config.json, weights, inputs and outputs .safetensors; or, for the refiner,
/// base/, model_difix.pkl, inputs and outputs .safetensors) and compare every output with the reference's;
/// fails when any is out of tolerance or was not compared.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The vector folder.
    #[arg(long)]
    vectors: PathBuf,
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    device: DeviceList,
    /// Checkpoint to load [default: DIR/weights.safetensors, else DIR/weights.pt; DIR/model_difix.pkl for the
    /// refiner].
    #[arg(long)]
    weights: Option<PathBuf>,
}

/// Prints the comparison table and a summary line; an error unless every output was compared and passed.
pub fn run(args: Args) -> Result<()> {
    let started = Instant::now();
    let dir = &args.vectors;
    let device = args.device.single()?;
    let report = if is_refiner_folder(dir) {
        tracing::info!("running the refiner of {} on {device:?}", dir.display());
        dggt_parity::refiner::run_parity(dir, args.weights.as_deref(), &device)
            .with_context(|| format!("running the refiner of {}", dir.display()))?
            .report
    } else {
        let vectors = ParityVectors::open(dir)?;
        let weights = match args.weights {
            Some(path) => path,
            None => vectors.default_weights()?,
        };
        tracing::info!("running {} with {} on {device:?}", dir.display(), weights.display());
        run_parity(&vectors, &weights, &device)
            .with_context(|| format!("running the network of {} with {}", dir.display(), weights.display()))?
            .report
    };
    print!("{report}");
    println!("{} ({:.1} s)", report.summary(), started.elapsed().as_secs_f64());
    outcome(&report)
}

/// An error naming every output that failed, compared or not.
fn outcome(report: &ParityReport) -> Result<()> {
    let failed: Vec<&str> = report.failed().map(|row| row.name.as_str()).collect();
    anyhow::ensure!(failed.is_empty(), "{} output(s) failed parity: {}", failed.len(), failed.join(", "));
    anyhow::ensure!(report.passed(), "no output was compared");
    Ok(())
}
