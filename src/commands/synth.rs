//! `dggt synth`: a procedural driving scene in the scene-export layout, optionally edited (objects removed or
//! moved) to give ground truth for scene editing.

use anyhow::{Context, Result};
use dggt_synth::{MoveFlag, ObjectEdit, ObjectId, SynthScene, SynthSummary};

use crate::commands::output::{self, OutputBoundArg, OutputFolderArgs, OutputKind};

/// A scene export written by `dggt synth`.
const OUTPUT: OutputKind = OutputKind { command: "synth", signature: "synth.json" };

/// Write a procedural driving scene (ray-cast ground truth) in the scene-export layout.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    output: OutputFolderArgs,
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
    /// Render the scene without object ID (an index into the scene's objects; the instance ids of
    /// `instances_info.json` are object ids). Repeatable.
    #[arg(long = "remove-object", value_name = "ID")]
    remove_object: Vec<ObjectId>,
    /// Render object ID moved at every time: by the offset DX,DY,DZ (metres, world axes: x along the road,
    /// y left, z up) after turning it by YAW_DEG degrees counter-clockwise seen from above, about its box centre
    /// at the first frame's time. Repeatable.
    #[arg(long = "move-object", value_name = "ID:DX,DY,DZ,YAW_DEG")]
    move_object: Vec<MoveFlag>,
    #[command(flatten)]
    bound: OutputBoundArg,
}

pub fn run(args: Args) -> Result<()> {
    let Args {
        output: OutputFolderArgs { out, overwrite },
        seed,
        frames,
        cameras,
        width,
        height,
        layout,
        lidar,
        remove_object,
        move_object,
        bound,
    } = args;
    let config = dggt_synth::SynthConfig { seed, frames, cameras, width, height };
    config.validate()?;
    let sweeps = if lidar { dggt_synth::Sweeps::Write } else { dggt_synth::Sweeps::Skip };
    let what = format!("{frames} frames x {cameras} cameras at {width}x{height}");
    bound.check(dggt_synth::largest_output_bytes(&config, sweeps), &what)?;
    let started = std::time::Instant::now();
    let scene = dggt_synth::generate(&config)?;
    let scene = edited(&scene, &remove_object, &move_object)?;
    output::prepare(&out, OUTPUT, overwrite.existing())?;
    let summary = dggt_synth::write_export(&scene, &out, layout, sweeps)
        .with_context(|| format!("writing the synthetic scene to {}", out.display()))?;
    println!(
        "wrote {} images ({} frames x {} cameras at {width}x{height}) and {} instances ({} moving) to {} ({layout} layout){} in {:.1} s",
        summary.images,
        summary.frames,
        summary.cameras,
        summary.instances,
        summary.moving_instances,
        out.display(),
        edit_note(&summary),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `scene` with the objects of `--remove-object` removed and those of `--move-object` moved.
fn edited(scene: &SynthScene, removals: &[ObjectId], moves: &[MoveFlag]) -> Result<SynthScene> {
    let mut edits: Vec<ObjectEdit> = removals.iter().map(|&id| ObjectEdit::Remove(id)).collect();
    for flag in moves {
        edits.push(flag.edit(scene).with_context(|| format!("--move-object {flag}"))?);
    }
    scene.edited(&edits).context("applying --remove-object and --move-object")
}

/// `, objects [..] removed and [..] moved` for an edited scene; empty otherwise.
fn edit_note(summary: &SynthSummary) -> String {
    let (removed, moved) = (&summary.removed_objects, &summary.moved_objects);
    match (removed.is_empty(), moved.is_empty()) {
        (true, true) => String::new(),
        (false, true) => format!(", objects {removed:?} removed"),
        (true, false) => format!(", objects {moved:?} moved"),
        (false, false) => format!(", objects {removed:?} removed and {moved:?} moved"),
    }
}
