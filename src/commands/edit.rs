//! `dggt edit`: the moving objects of a saved reconstruction removed, moved or inserted from another one,
//! rendered at chosen cameras and times.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use dggt_edit::{Edit, EditOptions, prepare_edits};
use dggt_refine::ReferenceView;

use crate::commands::output::{self, OutputKind};
use crate::commands::refine::{RefineJob, load_refiner, refine_files};
use crate::commands::render_output::RenderOutputArgs;

/// An edit's folder; `edit.json` is written once everything else is.
const OUTPUT: OutputKind = OutputKind { command: "edit", signature: "edit.json" };

/// Where the refined renders go (the unrefined ones stay in `renders/`).
const REFINED_RENDERS: &str = "renders_refined";

/// Edit the moving objects of a reconstruction (`dggt reconstruct`'s folder, or its `scene.safetensors`):
/// remove them, move them along their trajectories, insert objects of other reconstructions; renders, before/after
/// images, hole masks, per-time PLYs and `edit.json`. Positions and offsets are in the reconstruction's world
/// (its `cameras.json` frame and units); yaws in degrees, counter-clockwise seen from above (about the first
/// input camera's up, `-y` of its OpenCV axes). Instance ids are those of its `summary.json`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The reconstruction to edit: a `dggt reconstruct` output folder or its `scene.safetensors`.
    #[arg(long)]
    scene: PathBuf,
    /// Remove instance ID (repeatable).
    #[arg(long, value_name = "ID")]
    remove: Vec<String>,
    /// Move instance ID: at every time turned by YAW degrees about its centre and shifted by DX,DY,DZ world
    /// units (repeatable; moves of one instance add up).
    #[arg(long = "move", value_name = "ID:DX,DY,DZ,YAW", allow_hyphen_values = true)]
    moves: Vec<String>,
    /// Remove every Gaussian whose centre lies in the world-axis-aligned box between two opposite corners
    /// (static objects, which are no instance; repeatable).
    #[arg(long = "remove-box", value_name = "X0,Y0,Z0,X1,Y1,Z1", allow_hyphen_values = true)]
    remove_boxes: Vec<String>,
    /// Insert instance ID of another reconstruction (its folder or `scene.safetensors`): its first appearance's
    /// centre placed at X,Y,Z of this world, turned by YAW degrees; it keeps its motion (repeatable).
    #[arg(long, value_name = "SCENE:ID@X,Y,Z,YAW", allow_hyphen_values = true)]
    insert: Vec<String>,
    /// Rig cameras to render [default: every camera of the scene].
    #[arg(long, value_delimiter = ',')]
    cameras: Option<Vec<usize>>,
    /// Scene times to render (those of the reconstruction's input views, as `scene.safetensors` holds them)
    /// [default: the input views' times].
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    times: Option<Vec<f64>>,
    #[command(flatten)]
    output: RenderOutputArgs,
}

/// Checks every edit against the scene before the output folder is touched, then writes; with `--refine`,
/// refines every edited render into `renders_refined/`.
pub fn run(args: Args) -> Result<()> {
    let edits: Vec<Edit> = args
        .remove
        .iter()
        .map(|text| Edit::remove(text))
        .chain(args.moves.iter().map(|text| Edit::moved(text)))
        .chain(args.insert.iter().map(|text| Edit::insert(text)))
        .chain(args.remove_boxes.iter().map(|text| Edit::remove_box(text)))
        .collect::<Result<_, _>>()?;
    if edits.is_empty() {
        bail!("nothing to edit: give --remove, --move, --insert or --remove-box");
    }
    let named = [("--scene", Some(&args.scene))].into_iter().chain(args.output.refine.paths());
    output::refuse_inside_output(
        &args.output.folder.out,
        named.filter_map(|(flag, path)| Some((flag, path?.as_path()))),
    )?;
    let _lock = output::lock(&args.output.folder.out, "dggt edit")?;
    let refine = args.output.refine.spec()?;
    if refine.as_ref().is_some_and(|spec| spec.reference != ReferenceView::None) {
        bail!("--refine-reference: an edit has no input images beside its renders; use none");
    }
    let device = args.output.device.single()?;
    let options = EditOptions { scene: args.scene, edits, cameras: args.cameras, times: args.times };
    let job = prepare_edits(&options, &device)?;
    let what = format!("{} times x {} cameras", job.times.len(), job.cameras.len());
    args.output.bound.check(job.largest_output_bytes(), &what)?;
    let refiner = refine.as_ref().map(|spec| load_refiner(spec, &device)).transpose()?;
    output::prepare(&args.output.folder.out, OUTPUT, args.output.folder.overwrite.existing())?;
    let summary = job.write(&args.output.folder.out)?;
    for render in &summary.renders {
        println!(
            "time {:.3} camera {}: {} pixels changed, {} uncovered with nothing behind",
            render.time, render.camera, render.changed_pixels, render.hole_pixels
        );
    }
    if let (Some(refiner), Some(spec)) = (refiner, refine) {
        let jobs: Vec<RefineJob> = summary
            .renders
            .iter()
            .map(|render| RefineJob {
                image: args.output.folder.out.join(&render.file),
                reference: None,
                out: args
                    .output
                    .folder
                    .out
                    .join(REFINED_RENDERS)
                    .join(Path::new(&render.file).file_name().unwrap_or_default()),
            })
            .collect();
        refine_files(&refiner, &jobs, spec.latent, &device)?;
        println!("refined {} renders into {}", jobs.len(), args.output.folder.out.join(REFINED_RENDERS).display());
    }
    println!("{} edits written to {} (edit.json)", summary.edits.len(), args.output.folder.out.display());
    Ok(())
}
