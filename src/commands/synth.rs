//! `dggt synth`: a procedural driving scene in the scene-export layout.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::commands::output::{self, OutputBoundArg, OutputKind, OverwriteArg};

/// A scene export written by `dggt synth`.
const OUTPUT: OutputKind = OutputKind { command: "synth", signature: "synth.json" };

/// Write a procedural driving scene (ray-cast ground truth) in the scene-export layout.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder; must not exist or be empty.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    overwrite: OverwriteArg,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long, default_value_t = 20)]
    frames: usize,
    /// 1 = FRONT, 2 adds FRONT_LEFT, 3 adds FRONT_RIGHT.
    #[arg(long, default_value_t = 3)]
    cameras: usize,
    #[arg(long, default_value_t = 160)]
    width: u32,
    #[arg(long, default_value_t = 112)]
    height: u32,
    /// The export variant to write: waymo, waymo-storm, nuscenes or argoverse2.
    #[arg(long, default_value_t = dggt_data::ExportVariant::Waymo)]
    layout: dggt_data::ExportVariant,
    /// Also write ray-cast lidar sweeps (`lidar/{t}.bin`, about 0.6 MB a frame).
    #[arg(long)]
    lidar: bool,
    #[command(flatten)]
    bound: OutputBoundArg,
}

pub fn run(args: Args) -> Result<()> {
    let Args { out, overwrite, seed, frames, cameras, width, height, layout, lidar, bound } = args;
    let config = dggt_synth::SynthConfig { seed, frames, cameras, width, height };
    config.validate()?;
    let sweeps = if lidar { dggt_synth::Sweeps::Write } else { dggt_synth::Sweeps::Skip };
    let what = format!("{frames} frames x {cameras} cameras at {width}x{height}");
    bound.check(dggt_synth::largest_output_bytes(&config, sweeps), &what)?;
    output::prepare(&out, OUTPUT, overwrite.existing())?;
    let started = std::time::Instant::now();
    let summary = dggt_synth::synthesize(&config, &out, layout, sweeps)
        .with_context(|| format!("writing the synthetic scene to {}", out.display()))?;
    println!(
        "wrote {} images ({} frames x {} cameras at {width}x{height}) and {} instances ({} moving) to {} ({layout} layout) in {:.1} s",
        summary.images,
        summary.frames,
        summary.cameras,
        summary.instances,
        summary.moving_instances,
        out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
