//! `dggt reconstruct`: one forward pass over unposed images, written as cameras, maps, Gaussians and renders.

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::Result;
use dggt_infer::Architecture;
use dggt_model::Preset;
use dggt_reconstruct::{ReconstructOptions, TimeRequest, reconstruct};
use dggt_refine::ReferenceView;

use crate::commands::output::{self, OutputKind, StagedOutput};
use crate::commands::parse_range;
use crate::commands::refine::{RefineJob, load_refiner, refine_files};
use crate::commands::render_output::RenderOutputArgs;
use crate::commands::viewer::check_rerun_build;

/// Reconstruct a driving scene from unposed images with one forward pass: cameras (JSON, COLMAP, nerfstudio),
/// depth, dynamic and sky maps, Gaussians as PLY (static, sky, dynamic per time) and renders.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A folder of images (one camera), a folder of per-camera image folders, a glob pattern (quoted:
    /// `'log/*.jpg'` for one camera, `'log/cam*'` for a folder per camera), or a scene export.
    #[arg(long)]
    images: PathBuf,
    /// A trainer checkpoint folder (or run folder), or a release / VGGT `.pt` / `.safetensors` file.
    #[arg(long)]
    checkpoint: PathBuf,
    /// Architecture of a `.pt` / `.safetensors` checkpoint: a model `config.json`, or a training `.toml`
    /// (its model and preprocessing sections).
    #[arg(long, conflicts_with = "preset")]
    config: Option<PathBuf>,
    /// Architecture preset of a `.pt` / `.safetensors` checkpoint: tiny, vggt_1b, dggt [default: dggt].
    #[arg(long)]
    preset: Option<Preset>,
    /// Only these cameras (positions of the per-camera folders, or export camera ids).
    #[arg(long, value_delimiter = ',')]
    cameras: Option<Vec<usize>>,
    /// Only these frames, as `START..END` (end exclusive).
    #[arg(long, value_parser = parse_range)]
    frames: Option<Range<usize>>,
    /// Render at these times (seconds since the first chosen frame, within the input frames' times) [default:
    /// the input frames' times].
    #[arg(long, value_delimiter = ',', conflicts_with = "every")]
    times: Option<Vec<f64>>,
    /// Render K evenly spaced times per interval between input frames (1..=100).
    #[arg(long)]
    every: Option<usize>,
    /// Network input width, a multiple of 14 [default: the width the checkpoint was trained at, else the
    /// --config training file's, else 518].
    #[arg(long)]
    width: Option<u32>,
    /// Frames per chunk of the dense heads (lower uses less memory).
    #[arg(long, default_value_t = 4)]
    chunk: usize,
    #[command(flatten)]
    output: RenderOutputArgs,
    /// Also write the reconstruction as a rerun recording (`.rrd`: cameras, images, depth, masks, Gaussians,
    /// renders and objects on a time line; builds with the `rerun` feature). An existing file needs --overwrite.
    #[arg(long, value_name = "FILE.rrd")]
    rerun: Option<PathBuf>,
}

/// A reconstruction's folder; `summary.json` is written once the reconstruction is complete.
const OUTPUT: OutputKind = OutputKind { command: "reconstruct", signature: "summary.json" };

/// Where the refined renders go (the unrefined ones stay in `renders/`).
pub const REFINED_RENDERS: &str = "renders_refined";

/// Runs the reconstruction with progress on stderr and prints its summary; with `--refine`, refines every
/// render into `renders_refined/` under the same name (attending to its nearest input view in `images/` with
/// `--refine-reference nearest-input`). Everything is written beside `--out` and moved into place at the end.
pub fn run(args: Args) -> Result<()> {
    let named = [("--images", Some(&args.images)), ("--checkpoint", Some(&args.checkpoint))]
        .into_iter()
        .chain([("--config", args.config.as_ref()), ("--rerun", args.rerun.as_ref())])
        .chain(args.output.refine.paths())
        .filter_map(|(flag, path)| Some((flag, path?.as_path())));
    output::refuse_inside_output(&args.output.folder.out, named)?;
    let _lock = output::lock(&args.output.folder.out, "dggt reconstruct")?;
    if let Some(file) = &args.rerun {
        check_rerun_build("--rerun")?;
        output::prepare_file(file, "--rerun", args.output.folder.overwrite.existing())?;
    }
    let staged = StagedOutput::begin(&args.output.folder.out, OUTPUT, args.output.folder.overwrite.existing())?;
    let device = args.output.device.single()?;
    let refine = args.output.refine.spec()?;
    let refiner = refine.as_ref().map(|spec| load_refiner(spec, &device)).transpose()?;
    let mut options = ReconstructOptions::new(args.images, args.checkpoint, staged.path());
    options.architecture = match (args.config, args.preset) {
        (Some(path), _) => Some(Architecture::Config(path)),
        (None, Some(preset)) => Some(Architecture::Preset(preset)),
        (None, None) => None,
    };
    options.cameras = args.cameras;
    options.frames = args.frames;
    options.times = match (args.times, args.every) {
        (Some(times), _) => TimeRequest::Seconds(times),
        (None, Some(k)) => TimeRequest::Every(k),
        (None, None) => TimeRequest::Inputs,
    };
    options.width = args.width;
    options.chunk_frames = args.chunk;
    options.max_output_bytes = args.output.bound.bytes();
    options.progress = dggt_run::progress::Visibility::on_terminal();
    tracing::info!("reconstructing {} with {} on {device:?}", options.images.display(), options.checkpoint.display());
    let summary = reconstruct(&options, &device)?;
    println!("{summary}");
    if let (Some(refiner), Some(spec)) = (refiner, refine) {
        let jobs: Vec<RefineJob> = summary
            .renders
            .iter()
            .map(|render| {
                let name = Path::new(&render.file).file_name().unwrap_or_default();
                RefineJob {
                    image: options.out.join(&render.file),
                    reference: match spec.reference {
                        ReferenceView::None => None,
                        ReferenceView::NearestInput => Some(options.out.join(&render.nearest_input)),
                    },
                    out: options.out.join(REFINED_RENDERS).join(name),
                }
            })
            .collect();
        refine_files(&refiner, &jobs, spec.latent, &device)?;
        println!(
            "refined {} renders into {} (unrefined kept in renders/)",
            jobs.len(),
            args.output.folder.out.join(REFINED_RENDERS).display()
        );
    }
    staged.finish()?;
    if let Some(file) = &args.rerun {
        record(&args.output.folder.out, file)?;
    }
    println!("outputs: {} (summary.json)", args.output.folder.out.display());
    Ok(())
}

/// Writes the reconstruction in `folder` as a rerun recording at `file`.
#[cfg(feature = "rerun")]
fn record(folder: &Path, file: &Path) -> Result<()> {
    let report = dggt_rerun::record_reconstruction(folder, file)?;
    println!(
        "recording: {} ({:.1} MB, {} cameras, {} static splats, {} times) in {:.1} s",
        file.display(),
        report.bytes as f64 / 1e6,
        report.cameras,
        report.static_splats,
        report.dynamic_splats.len(),
        report.seconds
    );
    Ok(())
}

#[cfg(not(feature = "rerun"))]
fn record(_folder: &Path, _file: &Path) -> Result<()> {
    check_rerun_build("--rerun")
}
