//! The refiner: one image (optionally with a reference view) in, the cleaned image out, in one denoising
//! step.
//!
//! `image` and `reference` are NCHW RGB in [0, 1]. Views are stacked as batch rows `sample * views + view`
//! (view 0 the image), mapped to [-1, 1], padded at the bottom and right (edge pixels repeated) to a multiple
//! of 8, encoded to the posterior, scaled by the VAE's scaling factor, denoised at timestep 199 by the UNet
//! (in the reference mode its self-attention spans both views), stepped to the clean latent `x0`, decoded
//! with the encoder's skips, cropped back, and view 0 is returned clamped and mapped back to [0, 1]. Images,
//! latents and the result are f32; the UNet and the VAE may compute in f16 or bf16 ([`Refiner::with_precision`]).

use std::path::{Path, PathBuf};

use burn::tensor::ops::PadMode;
use burn::tensor::{Device, FloatDType, Tensor, TensorData};
use dggt_model::host::host_f32;
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};

use crate::checkpoint::DifixCheckpoint;
use crate::config::{SchedulerConfig, TextEncoderConfig, UnetConfig, VaeConfig, read_json, require};
use crate::error::RefineError;
use crate::lora::{VaeOverlay, apply_vae_overlay_scaled};
use crate::precision::RefinerPrecision;
use crate::reference::ReferenceView;
use crate::scheduler::{SingleStep, alphas_cumprod};
use crate::text_encoder::TextEncoder;
use crate::tokenizer::Prompt;
use crate::trace::Trace;
use crate::transformer::ViewAttention;
use crate::unet::Unet;
use crate::vae::Vae;
use crate::weights::{ParamNames, Weights, read_safetensors};

/// The timestep the refiner denoises at.
pub const TIMESTEP: usize = 199;

/// Image sides are padded to a multiple of this (the VAE's total downsampling).
const SIDE_MULTIPLE: usize = 8;

/// Which latent the encoder's posterior gives the UNet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Latent {
    /// The posterior mean: deterministic.
    PosteriorMean,
    /// `mean + std * n`, `n` standard normal drawn from `seed` (the deployed refiner's behaviour).
    Sampled { seed: u64 },
}

impl Latent {
    /// The latent of the `k`-th of several refinements: a sampled latent's seed advanced by `k`, so that each
    /// draws its own noise.
    pub fn nth(self, k: usize) -> Self {
        match self {
            Self::Sampled { seed } => Self::Sampled { seed: seed.wrapping_add(k as u64) },
            mean => mean,
        }
    }
}

/// What loading took from where.
#[derive(Debug, Clone, Default)]
pub struct LoadReport {
    /// UNet tensors the checkpoint supplied (the rest came from the base folder).
    pub unet_from_checkpoint: Vec<String>,
    /// Base UNet tensors the checkpoint did not replace.
    pub unet_from_base: usize,
    /// The checkpoint's changes to the VAE.
    pub vae: VaeOverlay,
    /// Tensors no module took, as `component: name`.
    pub unused: Vec<String>,
    /// The VAE's parameters by their diffusers names (after the checkpoint's overlay).
    pub vae_params: ParamNames,
    /// The UNet's parameters by their diffusers names.
    pub unet_params: ParamNames,
}

/// A refiner's modules and constants, for code that trains or transforms them ([`Refiner::into_parts`]).
pub struct RefinerParts {
    pub vae: Vae,
    pub unet: Unet,
    /// `[1, tokens, context_dim]`.
    pub prompt_embeds: Tensor<3>,
    pub step: SingleStep,
    pub scaling_factor: f32,
}

/// Where a refiner comes from and how it draws its latent: what a command that refines its renders carries
/// until it loads the refiner on its device.
#[derive(Debug, Clone, PartialEq)]
pub struct RefinerSpec {
    /// The base model folder (diffusers layout).
    pub model_dir: PathBuf,
    /// The Difix checkpoint, `.pkl` or converted `.safetensors`.
    pub checkpoint: PathBuf,
    pub prompt: Prompt,
    pub latent: Latent,
    /// The view each frame attends to (none: the single-view mode).
    pub reference: ReferenceView,
    pub precision: RefinerPrecision,
}

impl RefinerSpec {
    /// The refiner on `device`, in the spec's precision.
    pub fn load(&self, device: &Device) -> Result<(Refiner, LoadReport), RefineError> {
        let (refiner, report) = Refiner::load_prompt(&self.model_dir, &self.checkpoint, &self.prompt, device)?;
        Ok((refiner.with_precision(self.precision), report))
    }

    /// One line naming the folder, the checkpoint, the latent, the reference view and the precision.
    pub fn describe(&self) -> String {
        let latent = match self.latent {
            Latent::PosteriorMean => "posterior mean".to_string(),
            Latent::Sampled { seed } => format!("sampled latent, seed {seed}"),
        };
        let reference = match self.reference {
            ReferenceView::None => String::new(),
            view => format!(", reference view: {}", view.name()),
        };
        let precision = self.precision.name();
        format!("{} with {} ({latent}{reference}, {precision})", self.model_dir.display(), self.checkpoint.display())
    }
}

pub struct Refiner {
    pub(crate) vae: Vae,
    pub(crate) unet: Unet,
    /// `[1, tokens, context_dim]`.
    pub(crate) prompt_embeds: Tensor<3>,
    pub(crate) step: SingleStep,
    pub(crate) scaling_factor: f32,
}

impl Refiner {
    /// Loads the base model folder (diffusers layout: `vae/`, `unet/`, `text_encoder/`, `scheduler/`) with a
    /// Difix checkpoint over it (its `.pkl` or the `.safetensors` converted from it), and encodes the prompt
    /// given as token ids.
    pub fn load(
        model_dir: &Path,
        checkpoint: &Path,
        prompt_tokens: &[i64],
        device: &Device,
    ) -> Result<(Self, LoadReport), RefineError> {
        Self::from_checkpoint(model_dir, DifixCheckpoint::read(checkpoint)?, checkpoint, prompt_tokens, device)
    }

    /// [`Refiner::load`] with the checkpoint already read; `checkpoint_path` names it in messages.
    pub fn from_checkpoint(
        model_dir: &Path,
        checkpoint: DifixCheckpoint,
        checkpoint_path: &Path,
        prompt_tokens: &[i64],
        device: &Device,
    ) -> Result<(Self, LoadReport), RefineError> {
        let mut report = LoadReport::default();

        let vae_config_path = model_dir.join("vae/config.json");
        let vae_config: VaeConfig = read_json(&vae_config_path)?;
        check_vae(&vae_config, &vae_config_path)?;
        let vae_file = weights_file(&model_dir.join("vae"), "diffusion_pytorch_model")?;
        let mut vae_tensors = read_safetensors(&vae_file)?;
        report.vae = apply_vae_overlay_scaled(
            &mut vae_tensors,
            checkpoint.vae,
            &checkpoint.lora_targets,
            checkpoint.lora_rank,
            checkpoint.lora_alpha,
            checkpoint_path,
        )?;
        let mut vae_weights = Weights::new(vae_tensors, sources(&vae_file, checkpoint_path), device);
        let vae = Vae::load(&mut vae_weights, &vae_config)?;
        report.vae_params = vae_weights.params().clone();

        let unet_config_path = model_dir.join("unet/config.json");
        let unet_config: UnetConfig = read_json(&unet_config_path)?;
        let unet_file = weights_file(&model_dir.join("unet"), "diffusion_pytorch_model")?;
        let mut unet_tensors = read_safetensors(&unet_file)?;
        report.unet_from_checkpoint = checkpoint.unet.keys().cloned().collect();
        report.unet_from_base = unet_tensors.keys().filter(|name| !checkpoint.unet.contains_key(*name)).count();
        unet_tensors.extend(checkpoint.unet);
        let mut unet_weights = Weights::new(unet_tensors, sources(&unet_file, checkpoint_path), device);
        let unet = Unet::load(&mut unet_weights, &unet_config, &unet_config_path)?;
        report.unet_params = unet_weights.params().clone();

        let (prompt_embeds, text_unused) = encode_prompt(&model_dir.join("text_encoder"), prompt_tokens, device)?;

        let scheduler_path = model_dir.join("scheduler/scheduler_config.json");
        let scheduler: SchedulerConfig = read_json(&scheduler_path)?;
        let step = SingleStep::new(&alphas_cumprod(&scheduler, &scheduler_path)?, TIMESTEP)?;

        let unused = [("vae", vae_weights.unused()), ("unet", unet_weights.unused()), ("text_encoder", text_unused)];
        report.unused = unused
            .into_iter()
            .flat_map(|(part, names)| names.into_iter().map(move |n| format!("{part}: {n}")))
            .collect();
        let refiner = Self { vae, unet, prompt_embeds, step, scaling_factor: vae_config.scaling_factor };
        Ok((refiner, report))
    }

    /// The refiner's modules and constants.
    pub fn into_parts(self) -> RefinerParts {
        let Self { vae, unet, prompt_embeds, step, scaling_factor } = self;
        RefinerParts { vae, unet, prompt_embeds, step, scaling_factor }
    }

    /// The refiner made of `parts` (as [`Refiner::into_parts`] gave them, possibly trained since).
    pub fn from_parts(parts: RefinerParts) -> Self {
        let RefinerParts { vae, unet, prompt_embeds, step, scaling_factor } = parts;
        Self { vae, unet, prompt_embeds, step, scaling_factor }
    }

    /// [`Refiner::load`] with the prompt as text (tokenised by `model_dir/tokenizer/`; an error naming the
    /// missing file when the folder has none) or as token ids.
    pub fn load_prompt(
        model_dir: &Path,
        checkpoint: &Path,
        prompt: &Prompt,
        device: &Device,
    ) -> Result<(Self, LoadReport), RefineError> {
        Self::load(model_dir, checkpoint, &prompt.token_ids(model_dir)?, device)
    }

    /// The refiner with its UNet and VAE computing in `precision`'s types (the UNet's attention in f32 when its
    /// configuration upcasts it); images, latents and the result stay f32.
    pub fn with_precision(self, precision: RefinerPrecision) -> Self {
        Self {
            unet: self.unet.with_float_dtype(precision.unet),
            vae: self.vae.with_float_dtype(precision.vae),
            prompt_embeds: self.prompt_embeds.cast(precision.unet),
            ..self
        }
    }

    /// The prompt's text-encoder output `[1, tokens, context_dim]`, the UNet's cross-attention context.
    pub fn prompt_embeds(&self) -> &Tensor<3> {
        &self.prompt_embeds
    }

    /// Refines `image` `[batch, 3, h, w]` in [0, 1], attending to `reference` (same shape) when given.
    /// Returns `[batch, 3, h, w]` in [0, 1]. `trace` receives the intermediates under the parity vectors' names.
    pub fn refine(
        &self,
        image: Tensor<4>,
        reference: Option<Tensor<4>>,
        latent: Latent,
        trace: &mut Trace,
    ) -> Result<Tensor<4>, RefineError> {
        let [batch, channels, height, width] = image.dims();
        if channels != 3 || height == 0 || width == 0 {
            return Err(RefineError::Input(format!("image of shape {:?}, expected [batch, 3, h, w]", image.dims())));
        }
        let (views, rows) = match reference {
            None => (ViewAttention::PerView, image),
            Some(reference) if reference.dims() == image.dims() => {
                let rows = Tensor::stack::<5>(vec![image, reference], 1).reshape([2 * batch, channels, height, width]);
                (ViewAttention::Joint { views: 2 }, rows)
            }
            Some(reference) => {
                return Err(RefineError::Input(format!(
                    "reference of shape {:?}, expected the image's {:?}",
                    reference.dims(),
                    [batch, channels, height, width]
                )));
            }
        };
        let x = (rows - 0.5) / 0.5;
        trace.record("x_in", &x);
        let x = pad_to_multiple(x, SIDE_MULTIPLE);

        let posterior = self.vae.encode(x, trace);
        let latent = match latent {
            Latent::PosteriorMean => posterior.mean,
            Latent::Sampled { seed } => posterior.mean + posterior.std.clone() * standard_normal(&posterior.std, seed),
        } * self.scaling_factor;
        trace.record("latent", &latent);

        let context = self.prompt_embeds.clone().repeat_dim(0, latent.dims()[0]);
        let unet_dtype = self.prompt_embeds.dtype();
        let eps = self
            .unet
            .forward(latent.clone().cast(unet_dtype), self.step.timestep, &context, views, trace)
            .cast(FloatDType::F32);
        trace.record("unet.eps", &eps);
        let x0 = self.step.clean_latent(latent, eps);
        trace.record("x0", &x0);
        let decoder_input = x0 / self.scaling_factor;
        trace.record("dec.in", &decoder_input);
        let decoded = self.vae.decode(decoder_input, &posterior.down_inputs, trace);

        let decoded = decoded.narrow(2, 0, height).narrow(3, 0, width);
        let first_view = decoded.reshape([batch, views.views(), channels, height, width]).narrow(1, 0, 1);
        let image_out = first_view.reshape([batch, channels, height, width]).clamp(-1.0, 1.0) * 0.5 + 0.5;
        trace.record("image_out", &image_out);
        Ok(image_out)
    }
}

impl Refiner {
    /// Refines `frames` `[n, 3, h, w]` in [0, 1] in batches of `batch` frames (the reference-view mode when
    /// `reference` `[n, 3, h, w]` is given, frame `i` attending to reference `i`), calling `progress` with the
    /// number of frames done after each batch. A sampled latent draws batch `k`'s noise from `seed + k`, so
    /// results are reproducible for the same seed and batch size.
    // Burn's convention: frames in, frames out, tensors (ref-counted handles) taken by value as `refine` does.
    #[allow(clippy::needless_pass_by_value)]
    pub fn refine_frames(
        &self,
        frames: Tensor<4>,
        reference: Option<Tensor<4>>,
        latent: Latent,
        batch: usize,
        mut progress: impl FnMut(usize),
    ) -> Result<Tensor<4>, RefineError> {
        let count = frames.dims()[0];
        if batch == 0 || count == 0 {
            return Err(RefineError::Input(format!("{count} frames in batches of {batch}: nothing to refine")));
        }
        if let Some(reference) = &reference
            && reference.dims() != frames.dims()
        {
            return Err(RefineError::Input(format!(
                "references of shape {:?}, expected the frames' {:?}",
                reference.dims(),
                frames.dims()
            )));
        }
        let mut refined = Vec::with_capacity(count.div_ceil(batch));
        for (k, start) in (0..count).step_by(batch).enumerate() {
            let rows = batch.min(count - start);
            let part = reference.as_ref().map(|r| r.clone().narrow(0, start, rows));
            refined.push(self.refine(frames.clone().narrow(0, start, rows), part, latent.nth(k), &mut Trace::Off)?);
            progress(start + rows);
        }
        Ok(Tensor::cat(refined, 0))
    }
}

/// `[1, 3, h, w]` from interleaved RGB `[h, w, 3]` (a decoded image's layout).
pub fn frame_from_interleaved(
    rgb: &[f32],
    height: usize,
    width: usize,
    device: &Device,
) -> Result<Tensor<4>, RefineError> {
    if rgb.len() != 3 * height * width {
        return Err(RefineError::Input(format!("{} RGB values for a {width} x {height} frame", rgb.len())));
    }
    let hwc = Tensor::<3>::from_data(TensorData::new(rgb.to_vec(), [height, width, 3]), device);
    Ok(hwc.permute([2, 0, 1]).unsqueeze_dim(0))
}

/// Interleaved RGB `[h, w, 3]` of frame `index` of `frames` `[n, 3, h, w]`.
pub fn frame_to_interleaved(frames: &Tensor<4>, index: usize) -> Result<Vec<f32>, RefineError> {
    let [_, channels, height, width] = frames.dims();
    let hwc = frames.clone().narrow(0, index, 1).reshape([channels, height, width]).permute([1, 2, 0]);
    Ok(host_f32(hwc, &format!("frame {index}"))?)
}

/// Pads the bottom and right of `x` with copies of its edge pixels to sides that are multiples of `multiple`.
fn pad_to_multiple(x: Tensor<4>, multiple: usize) -> Tensor<4> {
    let [_, _, height, width] = x.dims();
    let extra = |side: usize| side.next_multiple_of(multiple) - side;
    if extra(height) == 0 && extra(width) == 0 {
        return x;
    }
    x.pad([(0, extra(height)), (0, extra(width))], PadMode::Edge)
}

/// Standard normal values shaped like `like`, from `seed` ([`standard_normal_values`]).
fn standard_normal(like: &Tensor<4>, seed: u64) -> Tensor<4> {
    let shape = like.dims();
    let values = standard_normal_values(shape.iter().product(), seed);
    Tensor::from_data(TensorData::new(values, shape), &like.device())
}

/// `count` standard normal values from `seed` (Box-Muller over a xoshiro256++ stream).
pub fn standard_normal_values(count: usize, seed: u64) -> Vec<f32> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let u1: f64 = 1.0 - rng.random::<f64>();
            let u2: f64 = rng.random::<f64>();
            ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
        })
        .collect()
}

/// The text encoder's output for the prompt, and the text-encoder tensors it did not use.
fn encode_prompt(dir: &Path, tokens: &[i64], device: &Device) -> Result<(Tensor<3>, Vec<String>), RefineError> {
    let config_path = dir.join("config.json");
    let config: TextEncoderConfig = read_json(&config_path)?;
    let file = weights_file(dir, "model")?;
    let mut weights = Weights::new(read_safetensors(&file)?, file.display().to_string(), device);
    let encoder = TextEncoder::load(&mut weights, &config, &config_path)?;
    Ok((encoder.forward(tokens)?, weights.unused()))
}

/// Settings of the VAE configuration this implementation does not cover are errors.
pub(crate) fn check_vae(config: &VaeConfig, path: &Path) -> Result<(), RefineError> {
    require(!config.block_out_channels.is_empty(), path, || "block_out_channels is empty".into())?;
    require(config.mid_block_add_attention, path, || "mid_block_add_attention false".into())?;
    require(config.use_quant_conv && config.use_post_quant_conv, path, || "quant convolutions turned off".into())
}

/// `<stem>.safetensors` in `dir`, or its `.fp16` variant.
pub fn weights_file(dir: &Path, stem: &str) -> Result<PathBuf, RefineError> {
    let candidates = [format!("{stem}.safetensors"), format!("{stem}.fp16.safetensors")];
    candidates
        .iter()
        .map(|name| dir.join(name))
        .find(|path| path.is_file())
        .ok_or_else(|| RefineError::file(dir, format!("no weights file (looked for {})", candidates.join(", "))))
}

fn sources(base: &Path, checkpoint: &Path) -> String {
    format!("{} with {}", base.display(), checkpoint.display())
}
