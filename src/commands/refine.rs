//! `dggt refine`: the diffusion refiner on its own — converting a Difix checkpoint to safetensors, refining
//! image files — and the options (`--refine MODEL_DIR` ...) and file loop other commands share to refine the
//! frames they render.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use burn::tensor::Device;
use clap::Subcommand;
use dggt_formats::images::{read_rgb_png, write_rgb_png};
use dggt_refine::checkpoint::DifixCheckpoint;
use dggt_refine::{
    Latent, Prompt, ReferenceView, Refiner, RefinerPrecision, RefinerSpec, frame_from_interleaved, frame_to_interleaved,
};
use dggt_run::progress::{Visibility, styled_bar};

use crate::backend::DeviceList;
use crate::commands::output::{self, OutputFolderArgs, OutputKind, OverwriteFileArg};

/// The single-step diffusion refiner (Difix on sd-turbo): convert its checkpoint, refine images.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    action: Action,
}

#[derive(Debug, Subcommand)]
enum Action {
    Convert(ConvertArgs),
    Images(ImagesArgs),
}

/// Convert a Difix checkpoint (`model_difix.pkl`) to safetensors (UNet and VAE tensors in f32, LoRA targets,
/// rank and alpha in the metadata); the refiner loads either.
#[derive(Debug, clap::Args)]
struct ConvertArgs {
    #[arg(long)]
    checkpoint: PathBuf,
    /// The `.safetensors` file to write.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    overwrite: OverwriteFileArg,
}

/// Refine image files, each written under the same name into the output folder, with `refined.json` saying
/// what was refined.
#[derive(Debug, clap::Args)]
struct ImagesArgs {
    /// The base model folder (diffusers layout: vae/, unet/, text_encoder/, scheduler/, tokenizer/).
    #[arg(long)]
    model: PathBuf,
    /// Difix checkpoint, `.pkl` or converted `.safetensors` [default: MODEL/model_difix.safetensors, else
    /// MODEL/model_difix.pkl].
    #[arg(long)]
    checkpoint: Option<PathBuf>,
    /// Images to refine.
    #[arg(long = "image", required = true)]
    images: Vec<PathBuf>,
    /// A reference view per image (the reference-view mode), in the images' order and of their sizes.
    #[arg(long = "reference")]
    references: Vec<PathBuf>,
    /// Prompt token ids, for a model folder without a tokenizer [default: "remove degradation" tokenised].
    #[arg(long, value_delimiter = ',')]
    prompt_ids: Option<Vec<i64>>,
    /// Float types: f32, f16, bf16 (both networks) or f16-unet, bf16-unet (the UNet alone, the VAE in f32).
    #[arg(long, default_value = "f32")]
    precision: RefinerPrecision,
    /// Draw the latent from the encoder's posterior instead of taking its mean.
    #[arg(long)]
    sample_latent: bool,
    /// Seed of the sampled latent.
    #[arg(long, default_value_t = 0, requires = "sample_latent")]
    seed: u64,
    /// Device: cpu, ndarray, wgpu[:N], cuda[:N].
    #[arg(long, default_value = "cpu")]
    device: DeviceList,
    #[command(flatten)]
    output: OutputFolderArgs,
}

/// A folder of refined images; `refined.json` (what was refined, with which refiner) is written last.
const REFINED_IMAGES: OutputKind = OutputKind { command: "refine images", signature: "refined.json" };

pub fn run(args: Args) -> Result<()> {
    match args.action {
        Action::Convert(args) => convert(&args),
        Action::Images(args) => images(args),
    }
}

fn convert(args: &ConvertArgs) -> Result<()> {
    output::prepare_file(&args.out, "--out", args.overwrite.existing())?;
    let checkpoint = DifixCheckpoint::read(&args.checkpoint)?;
    checkpoint.write_safetensors(&args.out)?;
    println!(
        "{}: {} UNet and {} VAE tensors, {} LoRA targets at rank {} (alpha {}) -> {}",
        args.checkpoint.display(),
        checkpoint.unet.len(),
        checkpoint.vae.len(),
        checkpoint.lora_targets.len(),
        checkpoint.lora_rank,
        checkpoint.lora_alpha,
        args.out.display()
    );
    Ok(())
}

fn images(args: ImagesArgs) -> Result<()> {
    anyhow::ensure!(
        args.references.is_empty() || args.references.len() == args.images.len(),
        "{} --reference for {} --image: give one per image or none",
        args.references.len(),
        args.images.len()
    );
    output::prepare(&args.output.out, REFINED_IMAGES, args.output.overwrite.existing())?;
    let device = args.device.single()?;
    let latent = if args.sample_latent { Latent::Sampled { seed: args.seed } } else { Latent::PosteriorMean };
    let mut spec = refiner_spec(&args.model, args.checkpoint.as_deref(), args.prompt_ids, latent)?;
    spec.precision = args.precision;
    let refiner = load_refiner(&spec, &device)?;
    let jobs: Vec<RefineJob> = args
        .images
        .iter()
        .enumerate()
        .map(|(i, image)| RefineJob {
            image: image.clone(),
            reference: args.references.get(i).cloned(),
            out: args.output.out.join(image.file_name().unwrap_or(image.as_os_str())),
        })
        .collect();
    refine_files(&refiner, &jobs, latent, &device)?;
    let record = serde_json::json!({
        "refiner": spec.describe(),
        "images": jobs.iter().map(|job| serde_json::json!({
            "image": job.image, "reference": job.reference, "refined": job.out,
        })).collect::<Vec<_>>(),
    });
    let path = args.output.out.join(REFINED_IMAGES.signature);
    std::fs::write(&path, serde_json::to_string_pretty(&record)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!("{} refined images in {}", jobs.len(), args.output.out.display());
    Ok(())
}

/// `--refine MODEL_DIR` and its companions, for commands that refine the frames they render.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RefineArgs {
    /// Also refine the rendered frames with the diffusion refiner of this model folder (diffusers layout:
    /// vae/, unet/, text_encoder/, scheduler/, tokenizer/).
    #[arg(long = "refine", value_name = "MODEL_DIR")]
    pub refine_model: Option<PathBuf>,
    /// The refiner's Difix checkpoint, `.pkl` or converted `.safetensors` [default:
    /// MODEL_DIR/model_difix.safetensors, else MODEL_DIR/model_difix.pkl].
    #[arg(long = "refine-checkpoint", requires = "refine_model")]
    pub refine_checkpoint: Option<PathBuf>,
    /// The refiner's prompt token ids, for a model folder without a tokenizer.
    #[arg(long = "refine-prompt-ids", value_delimiter = ',', requires = "refine_model")]
    pub refine_prompt_ids: Option<Vec<i64>>,
    /// Sample the refiner's latent with this seed [default: the posterior mean].
    #[arg(long = "refine-seed", requires = "refine_model")]
    pub refine_seed: Option<u64>,
    /// The view each frame attends to: none (single-view mode) or nearest-input (the input view of the
    /// frame's camera nearest in time: the reference-view mode).
    #[arg(long = "refine-reference", default_value = "none", requires = "refine_model")]
    pub refine_reference: ReferenceView,
    /// The refiner's float types: f32, f16, bf16 (both networks) or f16-unet, bf16-unet (the UNet alone).
    #[arg(long = "refine-precision", default_value = "f32", requires = "refine_model")]
    pub refine_precision: RefinerPrecision,
}

impl RefineArgs {
    /// The files these arguments name, each with its flag (for checks against the command's output folder).
    pub fn paths(&self) -> [(&'static str, Option<&PathBuf>); 2] {
        [("--refine", self.refine_model.as_ref()), ("--refine-checkpoint", self.refine_checkpoint.as_ref())]
    }

    /// The refiner these arguments name, if any.
    pub fn spec(&self) -> Result<Option<RefinerSpec>> {
        let Some(model) = &self.refine_model else { return Ok(None) };
        let latent = self.refine_seed.map_or(Latent::PosteriorMean, |seed| Latent::Sampled { seed });
        let mut spec = refiner_spec(model, self.refine_checkpoint.as_deref(), self.refine_prompt_ids.clone(), latent)?;
        spec.reference = self.refine_reference;
        spec.precision = self.refine_precision;
        Ok(Some(spec))
    }
}

/// The refiner of `model` with `checkpoint` (see [`RefineArgs::refine_checkpoint`] for the default) and the
/// prompt as token ids when given, else the default prompt through the folder's tokenizer; single-view, in f32.
pub fn refiner_spec(
    model: &Path,
    checkpoint: Option<&Path>,
    prompt_ids: Option<Vec<i64>>,
    latent: Latent,
) -> Result<RefinerSpec> {
    let checkpoint = match checkpoint {
        Some(path) => path.to_path_buf(),
        None => ["model_difix.safetensors", "model_difix.pkl"]
            .iter()
            .map(|name| model.join(name))
            .find(|path| path.is_file())
            .with_context(|| format!("no model_difix.safetensors or model_difix.pkl in {}", model.display()))?,
    };
    let prompt = prompt_ids.map_or_else(Prompt::default, Prompt::Tokens);
    let (reference, precision) = (ReferenceView::None, RefinerPrecision::default());
    Ok(RefinerSpec { model_dir: model.to_path_buf(), checkpoint, prompt, latent, reference, precision })
}

/// Loads the refiner `spec` names on `device`, warning about tensors it did not use.
pub fn load_refiner(spec: &RefinerSpec, device: &Device) -> Result<Refiner> {
    tracing::info!("loading the refiner {} on {device:?}", spec.describe());
    let (refiner, report) = spec.load(device).with_context(|| format!("loading the refiner {}", spec.describe()))?;
    if !report.unused.is_empty() {
        tracing::warn!("{} refiner tensors unused: {}", report.unused.len(), report.unused.join(", "));
    }
    Ok(refiner)
}

/// One image file to refine, optionally with its reference view, and where the result goes.
#[derive(Debug, Clone)]
pub struct RefineJob {
    pub image: PathBuf,
    pub reference: Option<PathBuf>,
    pub out: PathBuf,
}

/// Refines every job's image (8-bit PNG out), one frame at a time, with a progress bar. A sampled latent
/// draws job `i`'s noise from `seed + i`.
pub fn refine_files(refiner: &Refiner, jobs: &[RefineJob], latent: Latent, device: &Device) -> Result<()> {
    let bar = styled_bar(
        "refining {bar:30} {pos}/{len} [{elapsed_precise}]",
        Visibility::on_terminal(),
        Some(jobs.len() as u64),
    );
    let read = |path: &Path| -> Result<_> {
        let (size, rgb) = read_rgb_png(path)?;
        Ok((size, frame_from_interleaved(&rgb, size.height as usize, size.width as usize, device)?))
    };
    for (index, job) in jobs.iter().enumerate() {
        let (size, frame) = read(&job.image)?;
        let reference = match &job.reference {
            Some(path) => Some(read(path)?.1),
            None => None,
        };
        let refined = refiner
            .refine_frames(frame, reference, latent.nth(index), 1, |_| ())
            .with_context(|| format!("refining {}", job.image.display()))?;
        if let Some(parent) = job.out.parent() {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        write_rgb_png(&job.out, size, &frame_to_interleaved(&refined, 0)?)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(())
}
