//! `dggt refine-pairs`: renders training pairs for the refiner from a reconstruction run (its newest
//! checkpoint): the targets of the run's samples, at frames between their inputs, with the export's images
//! and an input view as reference, written to one pairs file, or with `--shards` to a folder of one file per
//! sample, that `refine-train` reads (`[pairs] rendered`).
//!
//! A sample that fails to load or render is reported and skipped; the run fails only when no sample gave
//! pairs. With `--shards` each sample's file is written as soon as it is rendered (memory stays that of one
//! sample) and samples whose file exists are kept, so a stopped run resumes where it stopped. The folder
//! records what its pairs were rendered from (`pairs-source.json`: the run and its checkpoint's step), and a
//! rerun continues only a folder rendered from the same; anything else is refused, so pairs of two
//! checkpoints never mix. A pairs file (without `--shards`) is never replaced unless told to.

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use dggt_refine_train::pair::RenderedPair;
use dggt_refine_train::pair_files::{shard_path, write_pairs};
use dggt_refine_train::render_pairs::{Reconstruction, render_pairs};
use dggt_run::Start;
use dggt_run::progress::{Visibility, progress_bar};
use dggt_train::{TrainConfig, Trainer};

use crate::backend::DeviceSpec;
use crate::commands::output::{self, Existing, OutputKind, OverwriteArg};
use crate::commands::parse_range;

/// Render refiner training pairs (frames with reconstruction artifacts and their ground truth).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The reconstruction run's training configuration; its newest checkpoint renders the pairs.
    #[arg(long)]
    config: PathBuf,
    /// The run's folder [default: the configuration's `out_dir`].
    #[arg(long)]
    run: Option<PathBuf>,
    /// The sample indices to render the targets of, `START..END`.
    #[arg(long, value_parser = parse_range)]
    samples: Range<usize>,
    /// The pairs file to write (safetensors), or with `--shards` the folder of per-sample files.
    #[arg(long)]
    out: PathBuf,
    /// Write one file per sample into the `--out` folder as it is rendered, keeping those already there.
    #[arg(long)]
    shards: bool,
    /// Replace the `--out` pairs file, or the shards of another run or checkpoint in the `--out` folder.
    #[command(flatten)]
    overwrite: OverwriteArg,
    #[arg(long, default_value = "cpu")]
    device: DeviceSpec,
}

/// What a folder of shards records about its pairs, written before the first shard.
const SHARD_SOURCE: &str = "pairs-source.json";

/// A folder of shards: every one holds [`SHARD_SOURCE`].
const SHARDS: OutputKind = OutputKind { command: "refine-pairs --shards", signature: SHARD_SOURCE };

/// What became of the samples.
#[derive(Debug, Default)]
struct Tally {
    pairs: usize,
    rendered: usize,
    kept: usize,
    failed: Vec<u64>,
}

pub fn run(args: &Args) -> Result<()> {
    let existing = args.overwrite.existing();
    let _lock = output::lock(&args.out, "dggt refine-pairs")?;
    if !args.shards {
        output::prepare_file(&args.out, "--out", existing)?;
    }
    let mut config = TrainConfig::load(&args.config)?;
    if let Some(run) = &args.run {
        config.run.out_dir = run.clone();
    }
    let device = args.device.device()?;
    let run = Trainer::new(config, vec![device.clone()], Start::Resume)?;
    if run.state().step == 0 {
        tracing::warn!("no checkpoint under the run's out_dir: rendering with the network as initialised");
    }
    if args.shards {
        let source = shard_source(run.config().run.out_dir.as_path(), run.state().step);
        prepare_shards(&args.out, &source, existing)?;
    }
    let bar = progress_bar(Visibility::on_terminal(), 0, args.samples.len() as u64);
    let reconstruction = Reconstruction {
        model: run.model(),
        objective: run.objective(),
        sampling: run.sampling(),
        preprocess: &run.config().data.preprocess,
    };
    let mut tally = Tally::default();
    let mut collected = Vec::new();
    for sample in args.samples.clone().map(|s| s as u64) {
        let shard = args.shards.then(|| shard_path(&args.out, sample));
        if shard.as_ref().is_some_and(|path| path.is_file()) {
            tally.kept += 1;
        } else {
            match render_pairs(reconstruction, [sample], &device) {
                Ok(pairs) => {
                    tally.rendered += 1;
                    tally.pairs += pairs.len();
                    match &shard {
                        Some(path) => write_pairs(&pairs, path)?,
                        None => collected.extend(pairs),
                    }
                }
                Err(error) => {
                    tracing::warn!("sample {sample} skipped: {error}");
                    tally.failed.push(sample);
                }
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    finish(args, &run, &tally, &collected)
}

/// What shards rendered by the run in `run` at checkpoint step `step` record.
fn shard_source(run: &Path, step: u64) -> serde_json::Value {
    let run = std::fs::canonicalize(run).unwrap_or_else(|_| run.to_owned());
    serde_json::json!({ "run": run, "step": step })
}

/// Readies the shard folder `dir` for pairs from `source`: a new or empty folder gets the record; a folder
/// recording the same source is continued; one recording another is refused, or emptied with `--overwrite`;
/// any other folder that is not empty is refused.
fn prepare_shards(dir: &Path, source: &serde_json::Value, existing: Existing) -> Result<()> {
    let record = dir.join(SHARD_SOURCE);
    let recorded: Option<serde_json::Value> = match std::fs::read(&record) {
        Ok(bytes) => Some(serde_json::from_slice(&bytes).with_context(|| format!("reading {}", record.display()))?),
        Err(_) => None,
    };
    match recorded {
        Some(recorded) if &recorded == source => {}
        Some(recorded) if existing == Existing::Refuse => anyhow::bail!(
            "{} holds pairs rendered from {recorded}, this run renders from {source}: choose another folder with \
             --out, or pass --overwrite to replace them",
            dir.display()
        ),
        _ => output::prepare(dir, SHARDS, existing)?,
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    std::fs::write(&record, serde_json::to_string_pretty(source)?)
        .with_context(|| format!("writing {}", record.display()))
}

/// Writes the collected pairs (without `--shards`) and prints what was done.
fn finish(args: &Args, run: &Trainer, tally: &Tally, collected: &[RenderedPair]) -> Result<()> {
    anyhow::ensure!(
        tally.rendered + tally.kept > 0,
        "no sample of {}..{} gave pairs (failed: {:?})",
        args.samples.start,
        args.samples.end,
        tally.failed
    );
    if !args.shards {
        write_pairs(collected, &args.out)?;
    }
    let failed = match tally.failed.as_slice() {
        [] => String::new(),
        samples => format!("; {} samples failed and were skipped: {samples:?}", samples.len()),
    };
    println!(
        "{} pairs from {} samples rendered ({} kept from an earlier run) of samples {}..{} of the run at step {}{failed}: {}",
        tally.pairs,
        tally.rendered,
        tally.kept,
        args.samples.start,
        args.samples.end,
        run.state().step,
        args.out.display()
    );
    Ok(())
}
