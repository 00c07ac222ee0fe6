//! `dggt inspect`: what a driving log holds.

use std::ops::Range;
use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::commands::parse_range;

/// Summarise a driving log: a scene export or a KITTI odometry sequence.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scene folder (export layout) or KITTI sequence folder.
    dir: PathBuf,
    /// Only these frame indices, as `START..END` (end exclusive).
    #[arg(long, value_parser = parse_range)]
    frames: Option<Range<usize>>,
    /// Only these camera ids (comma separated).
    #[arg(long, value_delimiter = ',')]
    cameras: Option<Vec<usize>>,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<()> {
    let scene = dggt_data::open_scene(&args.dir, args.frames, args.cameras)
        .with_context(|| format!("reading the log at {}", args.dir.display()))?;
    let summary = dggt_data::SceneSummary::of(&scene)
        .with_context(|| format!("summarising the log at {}", args.dir.display()))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{summary}");
    }
    Ok(())
}
