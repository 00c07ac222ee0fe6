//! `dggt stress`: the numerical stress suite.

use std::path::PathBuf;

use anyhow::{Context, Result};
use dggt_run::compute_pool::on_pool_worker;

use crate::backend::DeviceList;
use crate::commands::output::{self, OverwriteFileArg};

/// Drive the pipeline through extreme inputs and report every non-finite value by stage; fails when any case
/// does.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which cases: `bounded` (every case at small sizes), `full` (bigger scenarios, more random extreme
    /// mixtures) or `device` (what a GPU adds to the CPU suite: every crafted case and one network case).
    #[arg(long, value_enum, default_value = "bounded")]
    scope: Scope,
    /// A folder with `lpips_alex.safetensors` and `vgg16_features.safetensors`: adds LPIPS and Gram terms.
    #[arg(long)]
    loss_weights: Option<PathBuf>,
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    device: DeviceList,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    #[command(flatten)]
    overwrite: OverwriteFileArg,
}

/// [`dggt_stress::StressScope`] on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum Scope {
    Bounded,
    Full,
    Device,
}

impl From<Scope> for dggt_stress::StressScope {
    fn from(scope: Scope) -> Self {
        match scope {
            Scope::Bounded => Self::Bounded,
            Scope::Full => Self::Full,
            Scope::Device => Self::Device,
        }
    }
}

/// Runs the suite, prints the table; an error when any case fails.
pub fn run(args: Args) -> Result<()> {
    if let Some(path) = &args.json {
        output::prepare_file(path, "--json", args.overwrite.existing())?;
    }
    let device = args.device.single()?;
    let started = std::time::Instant::now();
    let options = dggt_stress::StressOptions { scope: args.scope.into(), loss_weights: args.loss_weights };
    // On one of rayon's threads: the host kernels' parallel operations keep a share of their work where called.
    let report = on_pool_worker(|| dggt_stress::run_suite(&options, &device))
        .map_err(|e| anyhow::anyhow!("stress suite: {e}"))?;
    print!("{}", report.table());
    println!("({:.1} s on {device:?})", started.elapsed().as_secs_f64());
    if let Some(path) = args.json {
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let failed: Vec<String> = report.failures().map(|c| format!("{} / {}", c.group, c.name)).collect();
    anyhow::ensure!(failed.is_empty(), "{} stress case(s) failed: {}", failed.len(), failed.join(", "));
    Ok(())
}
