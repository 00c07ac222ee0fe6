//! `dggt parity`: a folder of the release's reference vectors run and compared output by output.

use std::path::PathBuf;

use anyhow::{Context, Result};
use dggt_infer::parity::{ParityVectors, run_parity};

use crate::backend::DeviceList;

/// Run a folder of reference vectors (config.json, weights, inputs and outputs .safetensors) and compare every
/// output with the release's; fails when any is out of tolerance.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The vector folder.
    #[arg(long)]
    vectors: PathBuf,
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    device: DeviceList,
    /// Checkpoint to load [default: DIR/weights.safetensors, else DIR/weights.pt].
    #[arg(long)]
    weights: Option<PathBuf>,
}

/// Prints the comparison table and a summary line; an error when any output fails.
pub fn run(args: Args) -> Result<()> {
    let started = std::time::Instant::now();
    let dir = &args.vectors;
    let vectors = ParityVectors::open(dir)?;
    let weights = match args.weights {
        Some(path) => path,
        None => vectors.default_weights()?,
    };
    let device = args.device.single()?;
    tracing::info!("running {} with {} on {device:?}", dir.display(), weights.display());
    let report = run_parity(&vectors, &weights, &device)
        .with_context(|| format!("running the network of {} with {}", dir.display(), weights.display()))?;
    print!("{report}");
    println!("{} ({:.1} s)", report.summary(), started.elapsed().as_secs_f64());
    let failed: Vec<&str> = report.failed().map(|row| row.name.as_str()).collect();
    anyhow::ensure!(failed.is_empty(), "{} output(s) failed parity: {}", failed.len(), failed.join(", "));
    Ok(())
}
