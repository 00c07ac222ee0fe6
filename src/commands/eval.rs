//! `dggt eval`: the arguments, their translation into [`EvalOptions`], and the report printed.
//!
//! Defaults: the paper protocol, window `0..20`, cameras `0,1,2`, input stride 5 for the interpolation mode
//! (the paper's stride; the paper protocol fixes it, the reconstruction mode has none).

use std::ops::Range;
use std::path::PathBuf;

use anyhow::Result;
use dggt_eval::grid::CellSampling;
use dggt_eval::protocol::{DEFAULT_CAMERAS, DEFAULT_WINDOW, PAPER_EVERY};
use dggt_eval::{CropImages, EvalOptions, LpipsWeights, Protocol, evaluate};
use dggt_infer::{Architecture, CameraSource};
use dggt_model::Preset;

use crate::backend::DeviceList;
use crate::commands::output::{self, OutputKind, OverwriteArg};
use crate::commands::parse_range;
use crate::commands::refine::RefineArgs;

/// An evaluation's folder; `eval.json` is written with the report.
const OUTPUT: OutputKind = OutputKind { command: "eval", signature: "eval.json" };

/// Which protocol `--protocol` names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ProtocolChoice {
    /// Inputs at frames 0, 5, 10, 15 of the window; reconstruction and novel-view splits.
    Paper,
    /// Every frame of the window is an input and is scored.
    Reconstruction,
    /// Every `--every`-th frame is an input; inputs, in-between frames and frames after the last input reported
    /// separately.
    Interpolation,
}

/// Where `--poses` takes the cameras from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PosesChoice {
    /// The camera head's, targets interpolated between the inputs: the paper's unposed protocol.
    Predicted,
    /// The export's poses, relative to the first input view (how `render.cameras = "ground_truth"` trains).
    Export,
}

/// How `--cell-sampling` reads the render at a lidar cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CellSamplingChoice {
    /// Bilinear between the four nearest pixel centres (blends the two surfaces at a depth edge).
    Bilinear,
    /// The rendered pixel the cell's centre falls on (as the training's depth terms compare it).
    Pixel,
}

/// Arguments of `dggt eval`.
/// Evaluate a checkpoint on scene exports under the paper's or the release's protocol: PSNR, SSIM, LPIPS,
/// aligned depth RMSE and scene-flow metrics per view, split and scene; `eval.json` and `eval.md`.
#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// A scene export to evaluate (repeat for several).
    #[arg(long = "scene", required = true)]
    pub scenes: Vec<PathBuf>,
    /// A trainer checkpoint folder (or run folder), or a release `.pt` / `.safetensors` file.
    #[arg(long)]
    pub checkpoint: PathBuf,
    /// Architecture of a `.pt` / `.safetensors` checkpoint: a model `config.json` or a training `.toml`.
    #[arg(long, conflicts_with = "preset")]
    pub config: Option<PathBuf>,
    /// Architecture preset of a `.pt` / `.safetensors` checkpoint: tiny, vggt_1b, dggt [default: dggt].
    #[arg(long)]
    pub preset: Option<Preset>,
    #[arg(long, value_enum, default_value = "paper")]
    pub protocol: ProtocolChoice,
    /// Input stride of the interpolation protocol, 1..=(window length - 1) [default: 5].
    #[arg(long)]
    pub every: Option<usize>,
    /// The window, as frame indices `START..END` (end exclusive) [default: 0..20].
    #[arg(long, value_parser = parse_range)]
    pub frames: Option<Range<usize>>,
    /// Export camera ids (comma separated) [default: 0,1,2].
    #[arg(long, value_delimiter = ',')]
    pub cameras: Option<Vec<usize>>,
    /// Only these frames are scored besides the inputs (comma separated): the frames a training run held out
    /// (its `sampler.held_out`), so that no scored frame between the inputs was trained on [default: every
    /// frame of the window].
    #[arg(long, value_delimiter = ',')]
    pub score_frames: Option<Vec<usize>>,
    /// At most this many input frames per forward pass: a long window is evaluated in overlapping passes (each
    /// sharing its last input with the next), each frame scored by the pass whose inputs bracket it. Give the
    /// number of inputs the model was trained on [default: every input in one pass].
    #[arg(long)]
    pub inputs_per_pass: Option<usize>,
    /// Where the cameras come from: `predicted` (unposed) or `export`.
    #[arg(long, value_enum, default_value = "predicted")]
    pub poses: PosesChoice,
    /// How the rendered depth and flow are read at each lidar cell's centre.
    #[arg(long, value_enum, default_value = "bilinear")]
    pub cell_sampling: CellSamplingChoice,
    /// LPIPS linear weights (the lpips package's `alex.pth`, a full LPIPS state dict, or safetensors).
    #[arg(long)]
    pub lpips_weights: Option<PathBuf>,
    /// AlexNet features for LPIPS [default: the --lpips-weights file, for a full state dict].
    #[arg(long, requires = "lpips_weights")]
    pub alexnet: Option<PathBuf>,
    /// Network input width, a multiple of 14 [default: the width the checkpoint was trained at, else the
    /// --config training file's, else 518].
    #[arg(long)]
    pub width: Option<u32>,
    /// Frames per chunk of the dense heads (lower uses less memory).
    #[arg(long, default_value_t = 4)]
    pub chunk: usize,
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    pub device: DeviceList,
    /// Output folder of eval.json and eval.md; must not exist or be empty.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub overwrite: OverwriteArg,
    /// With `--refine MODEL_DIR`, every render is also scored after the diffusion refiner, side by side.
    #[command(flatten)]
    pub refine: RefineArgs,
    /// Also write `crops/<scene>/f<frame>_c<camera>.png` for every view between the inputs with moving objects:
    /// the truth around the dynamic mask, then the view drawn by each motion source (held, cross-fade,
    /// velocity, instances, learnt: those the model has), enlarged.
    #[arg(long)]
    pub crops: bool,
}

impl Args {
    /// The protocol these arguments describe.
    pub fn protocol(&self) -> Result<Protocol> {
        let window = self.frames.clone().unwrap_or(0..DEFAULT_WINDOW);
        let cameras = self.cameras.clone().unwrap_or_else(|| DEFAULT_CAMERAS.to_vec());
        let (start, length) = (window.start, window.len());
        let protocol = match self.protocol {
            ProtocolChoice::Paper => {
                Protocol { start, length, every: self.every.unwrap_or(PAPER_EVERY), cameras, ..Protocol::paper() }
            }
            ProtocolChoice::Reconstruction => {
                let mut protocol = Protocol::reconstruction(start, length, cameras);
                protocol.every = self.every.unwrap_or(1);
                protocol
            }
            ProtocolChoice::Interpolation => {
                Protocol::interpolation(start, length, self.every.unwrap_or(PAPER_EVERY), cameras)
            }
        };
        let protocol =
            Protocol { scored: self.score_frames.clone(), inputs_per_pass: self.inputs_per_pass, ..protocol };
        protocol.validate()?;
        Ok(protocol)
    }

    /// The evaluation these arguments ask for.
    pub fn options(&self) -> Result<EvalOptions> {
        check_distinct(&self.scenes)?;
        let mut options = EvalOptions::new(self.scenes.clone(), &self.checkpoint, &self.out);
        options.protocol = self.protocol()?;
        options.architecture = match (&self.config, &self.preset) {
            (Some(path), _) => Some(Architecture::Config(path.clone())),
            (None, Some(preset)) => Some(Architecture::Preset(*preset)),
            (None, None) => None,
        };
        options.width = self.width;
        options.chunk_frames = self.chunk;
        options.lpips = self.lpips_weights.as_ref().map(|linear| LpipsWeights {
            linear: linear.clone(),
            alexnet: self.alexnet.clone().unwrap_or_else(|| linear.clone()),
        });
        options.refine = self.refine.spec()?;
        options.crops = if self.crops { CropImages::Write } else { CropImages::Skip };
        options.poses = match self.poses {
            PosesChoice::Predicted => CameraSource::Predicted,
            PosesChoice::Export => CameraSource::GroundTruth,
        };
        options.cell_sampling = match self.cell_sampling {
            CellSamplingChoice::Pixel => CellSampling::Pixel,
            CellSamplingChoice::Bilinear => CellSampling::Bilinear,
        };
        Ok(options)
    }
}

/// Refuses a scene given twice (by the same path, or another path to the same folder): it would be scored
/// twice and counted as two scenes in the means.
fn check_distinct(scenes: &[PathBuf]) -> Result<()> {
    let mut seen = Vec::new();
    for scene in scenes {
        let folder = std::fs::canonicalize(scene).unwrap_or_else(|_| scene.clone());
        if seen.contains(&folder) {
            anyhow::bail!("--scene {} is given twice: give each scene once", scene.display());
        }
        seen.push(folder);
    }
    Ok(())
}

/// Runs the evaluation; prints the Markdown report followed by where the files are.
pub fn run(args: &Args) -> Result<()> {
    let device = args.device.single()?;
    let options = args.options()?;
    let named = args.scenes.iter().map(|scene| ("--scene", Some(scene)));
    let named = named
        .chain([("--checkpoint", Some(&args.checkpoint)), ("--config", args.config.as_ref())])
        .chain([("--lpips-weights", args.lpips_weights.as_ref()), ("--alexnet", args.alexnet.as_ref())])
        .chain(args.refine.paths())
        .filter_map(|(flag, path)| Some((flag, path?.as_path())));
    output::refuse_inside_output(&options.out, named)?;
    let _lock = output::lock(&options.out, "dggt eval")?;
    output::prepare(&options.out, OUTPUT, args.overwrite.existing())?;
    let report = evaluate(&options, &device)?;
    print!("{}", report.markdown());
    println!("\noutputs: {} and {}", options.out.join("eval.json").display(), options.out.join("eval.md").display());
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn parse(extra: &[&str]) -> Result<EvalOptions, String> {
        let mut argv = vec!["eval", "--scene", "s", "--checkpoint", "c", "--out", "o"];
        argv.extend_from_slice(extra);
        Cli::try_parse_from(argv)
            .map_err(|e| e.to_string())
            .and_then(|cli| cli.args.options().map_err(|e| e.to_string()))
    }

    #[test]
    fn arguments_the_protocol_cannot_take_are_refused() {
        assert!(parse(&["--protocol", "paper", "--every", "2"]).unwrap_err().contains("--every"));
        assert!(parse(&["--frames", "5..5"]).unwrap_err().contains("empty range"));
        assert!(parse(&["--protocol", "weird"]).is_err());
        assert!(parse(&["--device", "quantum"]).unwrap_err().contains("unknown device"));
        assert!(parse(&["--scene", "s"]).unwrap_err().contains("--scene s is given twice"));
        assert!(parse(&["--protocol", "interpolation", "--every", "30"]).unwrap_err().contains("give 1..=19"));
        let options =
            parse(&["--protocol", "interpolation", "--every", "3", "--frames", "4..11", "--cameras", "2"]).unwrap();
        assert_eq!(options.protocol.input_frames(), vec![4, 7, 10]);
        assert_eq!(options.protocol.cameras, vec![2]);
        assert!(parse(&["--inputs-per-pass", "3"]).unwrap_err().contains("the paper protocol is one pass"));
        let long = ["--protocol", "interpolation", "--every", "4", "--frames", "0..40", "--inputs-per-pass"];
        assert!(parse(&[&long[..], &["1"]].concat()).unwrap_err().contains("two inputs or more"));
        let passes = parse(&[&long[..], &["3"]].concat()).unwrap().protocol.passes();
        assert_eq!(passes.len(), 5, "inputs 0, 4, ..., 36 in passes of three sharing their ends");
        let paper = parse(&["--width", "84", "--preset", "tiny"]).unwrap();
        assert_eq!(paper.protocol, Protocol::paper());
        assert_eq!(paper.width, Some(84));
        assert_eq!(paper.architecture, Some(Architecture::Preset(Preset::Tiny)));
    }
}
