//! `dggt refine-pairs`: renders training pairs for the refiner from a reconstruction run (its newest
//! checkpoint): the targets of the run's samples, at frames between their inputs, with the export's images
//! and an input view as reference, written to one pairs file that `refine-train` reads (`[pairs] rendered`).

use std::ops::Range;
use std::path::PathBuf;

use anyhow::Result;
use dggt_refine_train::render_pairs::{render_pairs, write_pairs};
use dggt_train::trainer::progress_bar;
use dggt_train::{Start, TrainConfig, Trainer};

use crate::backend::DeviceSpec;
use crate::commands::parse_range;

/// Render refiner training pairs (frames with reconstruction artifacts and their ground truth).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The reconstruction run's training configuration; its newest checkpoint renders the pairs.
    #[arg(long)]
    config: PathBuf,
    /// The sample indices to render the targets of, `START..END`.
    #[arg(long, value_parser = parse_range)]
    samples: Range<usize>,
    /// The pairs file to write (safetensors).
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value = "cpu")]
    device: DeviceSpec,
}

pub fn run(args: Args) -> Result<()> {
    let config = TrainConfig::load(&args.config)?;
    let device = args.device.device()?;
    let run = Trainer::new(config, vec![device.clone()], Start::Resume)?;
    if run.state().step == 0 {
        tracing::warn!("no checkpoint under the run's out_dir: rendering with the network as initialised");
    }
    let bar = progress_bar(std::io::IsTerminal::is_terminal(&std::io::stderr()), 0, args.samples.len() as u64);
    let mut pairs = Vec::new();
    for sample in args.samples.clone() {
        pairs.extend(render_pairs(&run, [sample as u64], &device)?);
        bar.inc(1);
    }
    bar.finish_and_clear();
    write_pairs(&pairs, &args.out)?;
    println!(
        "{} pairs from samples {}..{} of the run at step {}: {}",
        pairs.len(),
        args.samples.start,
        args.samples.end,
        run.state().step,
        args.out.display()
    );
    Ok(())
}
