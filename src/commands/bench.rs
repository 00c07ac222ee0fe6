//! `dggt bench`: the speed/accuracy sweep (the arguments, the sweep they describe, and the run that prints the
//! table and writes `bench.csv`, `bench.png`, `bench.svg` and `bench-notes.txt`), or with `compute` the suite of
//! [`super::bench_compute`].

use std::path::{Path, PathBuf};

use anyhow::Result;
use dggt_bench::knobs::parse_opacity;
use dggt_bench::{
    BenchOptions, Culling, Knobs, LpipsFiles, Precision, Skips, SweepSpec, parse_motion, report, run_bench,
    write_outputs,
};
use dggt_infer::{CameraSource, SkyChoice};

use crate::backend::DeviceList;
use crate::commands::output::{self, OutputKind, OverwriteArg};
use crate::commands::refine::RefineArgs;
use crate::commands::{bench_compute, bench_refiner};

/// Benchmarks: without a suite, run time against error over the reconstruction's knobs on a scene; `compute`
/// times the network, a training step and the rasteriser at the release's scale.
#[derive(Debug, Clone, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Args {
    #[command(subcommand)]
    suite: Option<Suite>,
    /// Not an `Option`: clap never fills a flattened `Option` whose struct flattens groups of its own (the
    /// overwrite and refiner arguments), so the sweep's required files are checked when it runs.
    #[command(flatten)]
    sweep: SweepArgs,
}

#[derive(Debug, Clone, clap::Subcommand)]
enum Suite {
    /// The network, a training step and the rasteriser at the release's scale, beside the reference's figures.
    Compute(bench_compute::Args),
    /// The compute suite's table from record files (ours in parts, and the references').
    Table(bench_compute::TableArgs),
    /// The diffusion refiner's time per frame and peak memory (made-up weights, sd-turbo's size by default).
    Refiner(bench_refiner::Args),
}

/// Runs the suite the arguments name.
pub fn run(args: Args) -> Result<()> {
    match args.suite {
        Some(Suite::Compute(compute)) => bench_compute::run(&compute),
        Some(Suite::Table(table)) => bench_compute::run_table(&table),
        Some(Suite::Refiner(refiner)) => bench_refiner::run(&refiner),
        None => run_sweep(&args.sweep),
    }
}

/// Measure run time against error over the knobs that trade speed for accuracy: input width, input frames,
/// culling threshold, precision, sky, the shortcuts that skip what a scene does not need. A baseline, the exact render (culling off) and one row per other value
/// of each knob (`--grid` adds every combination).
#[derive(Debug, Clone, clap::Args)]
pub struct SweepArgs {
    /// A scene export (its images are the ground truth of the target frames); required for the sweep.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// A trainer checkpoint folder (or run folder) or release file [default: a fresh tiny model with a fixed
    /// seed, whose ground-truth error is meaningless].
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    pub device: DeviceList,
    /// Timed repetitions per configuration (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Untimed warm-up runs per configuration.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// Export camera ids.
    #[arg(long, value_delimiter = ',', default_value = "0")]
    pub cameras: Vec<usize>,
    /// Target frames (positions in the scene) [default: 2, 7, 12, ... short of the last two frames].
    #[arg(long, value_delimiter = ',')]
    pub targets: Option<Vec<usize>>,
    /// Baseline network input width (px, a multiple of 14); also the resolution every error is measured at.
    #[arg(long, default_value_t = 84)]
    pub width: u32,
    /// Widths to sweep.
    #[arg(long, value_delimiter = ',', default_value = "56,84,112,168")]
    pub widths: Vec<u32>,
    /// Baseline number of input frames.
    #[arg(long, default_value_t = 8)]
    pub frames: usize,
    /// Input frame counts to sweep.
    #[arg(long = "frame-counts", value_delimiter = ',', default_value = "4,8,16")]
    pub frame_counts: Vec<usize>,
    /// Baseline culling threshold on the opacity after the lifespan fade (a number or N/D).
    #[arg(long, default_value = "1/255")]
    pub min_opacity: String,
    /// Culling thresholds to sweep.
    #[arg(long, value_delimiter = ',', default_value = "1/255,0.01,0.05")]
    pub min_opacities: Vec<String>,
    /// Baseline precision of the network: f32, f16, bf16.
    #[arg(long, default_value = "f32")]
    pub precision: String,
    /// Precisions to sweep (unsupported ones are reported as skipped).
    #[arg(long, value_delimiter = ',', default_value = "f32,f16,bf16")]
    pub precisions: Vec<String>,
    /// Baseline without the sky model.
    #[arg(long)]
    pub no_sky: bool,
    /// Sky settings to sweep (`on`, `off`).
    #[arg(long, value_delimiter = ',', default_value = "on,off")]
    pub sky: Vec<String>,
    /// Baseline shortcuts that leave out what a scene does not need: `none`, `motion` (the motion head only
    /// on frames that may hold dynamic pixels), `sky` (no sky render behind a covered view), `all`.
    #[arg(long, default_value = "none")]
    pub skip: String,
    /// Shortcuts to sweep.
    #[arg(long, value_delimiter = ',', default_value = "none,motion,sky,all")]
    pub skips: Vec<String>,
    /// Baseline motion of the dynamic Gaussians between inputs: `velocity` (the predicted velocities, held
    /// without them), `held` (where predicted), `instances` (the objects among the dynamic pixels moved along
    /// their trajectories) or `learnt` (along the flow head's learnt flow; a network with a flow head).
    #[arg(long, default_value = "velocity")]
    pub motion: String,
    /// Motions to sweep.
    #[arg(long, value_delimiter = ',', default_value = "held,velocity,instances")]
    pub motions: Vec<String>,
    /// Also measure every combination of the swept values.
    #[arg(long)]
    pub grid: bool,
    /// Cameras from the camera head instead of the export's poses.
    #[arg(long)]
    pub predicted_poses: bool,
    /// LPIPS-Alex: the AlexNet backbone weights (`.pth` / `.safetensors`).
    #[arg(long, requires = "lpips_linear")]
    pub lpips_backbone: Option<PathBuf>,
    /// LPIPS-Alex: the linear-layer weights (the lpips package's `alex.pth`); may be the backbone's file.
    #[arg(long, requires = "lpips_backbone")]
    pub lpips_linear: Option<PathBuf>,
    /// Seed of the fresh model (without --checkpoint).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Frames per chunk of the dense heads.
    #[arg(long, default_value_t = 4)]
    pub chunk: usize,
    /// Output folder; must not exist or be empty; required for the sweep.
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub overwrite: OverwriteArg,
    /// With `--refine MODEL_DIR`, every row's renders are also refined: its time and its error against the
    /// truth beside the unrefined one.
    #[command(flatten)]
    pub refine: RefineArgs,
}

fn parse_sky(text: &str) -> Result<SkyChoice> {
    match text.trim().to_ascii_lowercase().as_str() {
        "on" | "true" | "yes" => Ok(SkyChoice::Render),
        "off" | "false" | "no" => Ok(SkyChoice::Skip),
        other => anyhow::bail!("--sky: `{other}`: expected on or off"),
    }
}

impl SweepArgs {
    /// The options these arguments describe, for the sweep of `scene`.
    pub fn options(&self, scene: &Path) -> Result<BenchOptions> {
        let sweep = SweepSpec {
            baseline: Knobs {
                width: self.width,
                input_frames: self.frames,
                culling: Culling::MinOpacity(parse_opacity(&self.min_opacity)?),
                precision: Precision::parse(&self.precision)?,
                sky: if self.no_sky { SkyChoice::Skip } else { SkyChoice::Render },
                skips: Skips::parse(&self.skip)?,
                motion: parse_motion(&self.motion)?,
            },
            widths: self.widths.clone(),
            input_frames: self.frame_counts.clone(),
            min_opacities: self.min_opacities.iter().map(|t| parse_opacity(t)).collect::<Result<_, _>>()?,
            precisions: self.precisions.iter().map(|t| Precision::parse(t)).collect::<Result<_, _>>()?,
            sky: self.sky.iter().map(|t| parse_sky(t)).collect::<Result<_, _>>()?,
            skips: self.skips.iter().map(|t| Skips::parse(t)).collect::<Result<_, _>>()?,
            motions: self.motions.iter().map(|t| parse_motion(t)).collect::<Result<_, _>>()?,
            full_grid: self.grid,
        };
        Ok(BenchOptions {
            scene: scene.to_path_buf(),
            checkpoint: self.checkpoint.clone(),
            cameras: self.cameras.clone(),
            targets: self.targets.clone(),
            sweep,
            repeat: self.repeat,
            warmup: self.warmup,
            poses: if self.predicted_poses { CameraSource::Predicted } else { CameraSource::GroundTruth },
            lpips: match (&self.lpips_backbone, &self.lpips_linear) {
                (Some(backbone), Some(linear)) => {
                    Some(LpipsFiles { backbone: backbone.clone(), linear: linear.clone() })
                }
                _ => None,
            },
            seed: self.seed,
            chunk_frames: self.chunk,
            refine: self.refine.spec()?,
        })
    }
}

/// A sweep's folder; `bench-notes.txt` is written last.
const SWEEP_OUTPUT: OutputKind = OutputKind { command: "bench", signature: "bench-notes.txt" };

/// Runs the sweep, writes the outputs and prints the table, the notes and where the files are.
fn run_sweep(args: &SweepArgs) -> Result<()> {
    let (Some(scene), Some(out)) = (&args.scene, &args.out) else {
        anyhow::bail!("dggt bench needs --scene and --out (the sweep), or a suite (`compute`, `table`, `refiner`)");
    };
    let device = args.device.single()?;
    let options = args.options(scene)?;
    let _lock = output::lock(out, "dggt bench")?;
    output::prepare(out, SWEEP_OUTPUT, args.overwrite.existing())?;
    let report = run_bench(&options, &device)?;
    let files = write_outputs(&report, out)?;
    print!("{}", report::table_text(&report));
    print!("{}", report::notes_text(&report));
    println!(
        "outputs: {}, {}{}, {}, {}",
        files.csv.display(),
        files.png.display(),
        if files.png_has_text { "" } else { " (no font found: no text; see the SVG)" },
        files.svg.display(),
        files.notes.display()
    );
    Ok(())
}
