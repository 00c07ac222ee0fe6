//! `dggt curves`: the training curves of one or more runs as one PNG ([`dggt_bench::curves`]), and per run its
//! last and best validation PSNR.

use std::path::PathBuf;

use anyhow::{Result, bail};
use dggt_bench::curves::{RunCurves, best_point, default_label, draw_curves};

use crate::commands::output::{self, OverwriteFileArg};

/// Draw the training curves of runs from their metrics: validation PSNR and smoothed training loss against
/// step, one colour per run.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Run folders of `dggt train` (or their `metrics.jsonl` files).
    #[arg(required = true, value_name = "RUN")]
    runs: Vec<PathBuf>,
    /// The PNG to write (its folder is created when missing).
    #[arg(long, value_name = "FILE.png")]
    out: PathBuf,
    /// The runs' names in the legend, comma-separated, one per run [default: each run folder's name].
    #[arg(long, value_delimiter = ',')]
    labels: Option<Vec<String>>,
    #[command(flatten)]
    overwrite: OverwriteFileArg,
}

/// Reads every run, draws them, prints the file and each run's validation PSNR.
pub fn run(args: Args) -> Result<()> {
    let labels = match args.labels {
        Some(labels) if labels.len() != args.runs.len() => {
            bail!("--labels gives {} labels for {} runs: one label per run", labels.len(), args.runs.len())
        }
        Some(labels) => labels,
        None => args.runs.iter().map(|run| default_label(run)).collect(),
    };
    output::prepare_file(&args.out, "--out", args.overwrite.existing())?;
    let runs = args
        .runs
        .iter()
        .zip(labels)
        .map(|(path, label)| RunCurves::read(path, label))
        .collect::<Result<Vec<_>, _>>()?;
    draw_curves(&runs, &args.out)?;
    println!("curves: {}", args.out.display());
    for run in &runs {
        println!("{}", psnr_line(run));
    }
    Ok(())
}

/// `LABEL: validation PSNR last .. dB (step ..), best .. dB at step ..`, with the average's too when it was scored.
fn psnr_line(run: &RunCurves) -> String {
    let summary = |series: &[(u64, f64)]| {
        let (&(last_step, last), (best_step, best)) = (series.last()?, best_point(series)?);
        Some(format!("last {last:.2} dB (step {last_step}), best {best:.2} dB at step {best_step}"))
    };
    let mut line = match summary(&run.validation_trained) {
        Some(trained) => format!("{}: validation PSNR {trained}", run.label),
        None => format!("{}: no validation of the trained weights", run.label),
    };
    if let Some(average) = summary(&run.validation_average) {
        line.push_str(&format!("; average weights {average}"));
    }
    line
}
