//! `dggt parity`: a folder of the release's reference vectors run and compared output by output. A folder of
//! the refiner's vectors (`base/`, `model_difix.pkl`, inputs and outputs) runs the refiner instead.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use burn::tensor::Device;
use dggt_infer::parity::{ParityVectors, run_parity};

use crate::backend::DeviceList;

/// Run a folder of reference vectors (config.json, weights, inputs and outputs .safetensors; or, for the refiner,
/// base/, model_difix.pkl, inputs and outputs .safetensors) and compare every output with the reference's;
/// fails when any is out of tolerance.
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

/// Prints the comparison table and a summary line; an error when any output fails.
pub fn run(args: Args) -> Result<()> {
    let started = Instant::now();
    let dir = &args.vectors;
    if dggt_refine::parity::is_refiner_folder(dir) {
        return run_refiner(dir, args.weights.as_deref(), &args.device.single()?, started);
    }
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

/// The refiner's vectors: both modes, every stored tensor.
fn run_refiner(dir: &Path, checkpoint: Option<&Path>, device: &Device, started: Instant) -> Result<()> {
    tracing::info!("running the refiner of {} on {device:?}", dir.display());
    let report = dggt_refine::parity::run_parity(dir, checkpoint, device)
        .with_context(|| format!("running the refiner of {}", dir.display()))?;
    print!("{report}");
    println!("{} ({:.1} s)", report.summary(), started.elapsed().as_secs_f64());
    let failed: Vec<&str> = report.failed().map(|row| row.name.as_str()).collect();
    anyhow::ensure!(failed.is_empty(), "{} tensor(s) failed parity: {}", failed.len(), failed.join(", "));
    Ok(())
}
