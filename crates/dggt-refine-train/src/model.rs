//! The refiner made trainable, as Difix trains it: the UNet trained fully; in the VAE the skip convolutions
//! trained, the decoder's LoRA kept as separate low-rank factors over its frozen weights, everything else
//! (the encoder included) frozen, so no gradient reaches it.
//!
//! The LoRA factors are burn [`LoraAdapter`]s attached to the decoder's weight parameters: the stored weight
//! stays the frozen base and the layer sees `base + (alpha / r) · reshape(a @ b)`, `a` and `b` being their
//! own trainable parameters. Convolution `[out, in, k, k]`: `a` is peft's `lora_B` `[out, r]` and `b` its
//! `lora_A` flattened `[r, in·k·k]` (the convolution is linear in its kernel, so this equals peft's branch
//! `base(x) + scale · lora_B(lora_A(x))`); linear (burn's `[in, out]`): `a = lora_Aᵀ`, `b = lora_Bᵀ`. They are
//! merged into the weights only by the refiner's loader, from a Difix checkpoint written of the trained
//! weights.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;

use burn::module::{LoraAdapter, Module, ModuleVisitor, Param, ParamId, Reparameterizer};
use burn::tensor::{Device, Tensor, TensorData};
use dggt_refine::checkpoint::DifixCheckpoint;
use dggt_refine::lora::{LORA_ALPHA, LoraPair, split_lora_pairs};
use dggt_refine::scheduler::SingleStep;
use dggt_refine::unet::Unet;
use dggt_refine::vae::Vae;
use dggt_refine::weights::{HostTensor, ParamNames, StoredLayout};
use dggt_refine::{Latent, Refiner, RefinerParts, Trace};

use crate::error::RefineTrainError;

/// The refiner's parameters: what the optimiser steps and checkpoints hold.
#[derive(Module, Debug)]
pub struct RefinerWeights {
    pub vae: Vae,
    pub unet: Unet,
}

/// The parameters of one LoRA target's factors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Adapter {
    pub a: ParamId,
    pub b: ParamId,
    /// The layout of the target's weight (convolution kernel as in the file, or a transposed linear weight).
    pub layout: StoredLayout,
}

/// Where each parameter came from, by the names of diffusers and peft.
#[derive(Debug, Clone)]
pub struct ParamIndex {
    pub vae: ParamNames,
    pub unet: ParamNames,
    /// LoRA targets (VAE module names) and their factors.
    pub adapters: BTreeMap<String, Adapter>,
    pub rank: usize,
}

/// A refiner whose weights take gradients ([`RefinerWeights`]) and the constants of its forward pass.
#[derive(Debug, Clone)]
pub struct TrainableRefiner {
    pub weights: RefinerWeights,
    pub index: ParamIndex,
    /// `[1, tokens, context_dim]`, detached from the text encoder.
    prompt_embeds: Tensor<3>,
    step: SingleStep,
    scaling_factor: f32,
}

/// Whether a VAE parameter trains (the skip convolutions do; their LoRA factors always do).
fn vae_trains(name: &str) -> bool {
    name.starts_with("decoder.skip_conv_")
}

impl TrainableRefiner {
    /// Loads the diffusers folder with a Difix checkpoint over it (`model_difix.pkl`, or its safetensors form
    /// as a trained refiner is written), its LoRA factors the starting point, on `device` (an autodiff device to train).
    pub fn load(
        base_dir: &Path,
        checkpoint_path: &Path,
        prompt_tokens: &[i64],
        device: &Device,
    ) -> Result<Self, RefineTrainError> {
        Self::from_checkpoint(base_dir, DifixCheckpoint::read(checkpoint_path)?, checkpoint_path, prompt_tokens, device)
    }

    /// [`TrainableRefiner::load`] with the checkpoint given (`source` names it in messages), for example a
    /// fresh one ([`crate::fresh`]).
    pub fn from_checkpoint(
        base_dir: &Path,
        mut checkpoint: DifixCheckpoint,
        checkpoint_path: &Path,
        prompt_tokens: &[i64],
        device: &Device,
    ) -> Result<Self, RefineTrainError> {
        let (plain, mut pairs) = split_lora_pairs(std::mem::take(&mut checkpoint.vae));
        let targets = std::mem::take(&mut checkpoint.lora_targets);
        let rank = checkpoint.lora_rank;
        let base = DifixCheckpoint { vae: plain, ..checkpoint };
        let (refiner, report) = Refiner::from_checkpoint(base_dir, base, checkpoint_path, prompt_tokens, device)?;
        let lora_error = |module: &str, detail: &str| RefineTrainError::Lora {
            checkpoint: checkpoint_path.to_path_buf(),
            module: module.to_string(),
            detail: detail.to_string(),
        };
        let mut factors = HashMap::new();
        for target in &targets {
            let pair = pairs.remove(target).ok_or_else(|| lora_error(target, "no lora_A / lora_B pair"))?;
            let &(id, layout) = report
                .vae_params
                .get(&format!("{target}.weight"))
                .ok_or_else(|| lora_error(target, "not a weight of the VAE"))?;
            let (a, b) =
                burn_factors(pair, layout, rank, device).map_err(|fault| lora_error(target, &fault.to_string()))?;
            factors.insert(id, (target.clone(), a, b, layout));
        }
        if let Some(stray) = pairs.keys().next() {
            return Err(lora_error(stray, "has a LoRA pair but is not a target"));
        }
        let trainable: HashSet<ParamId> =
            report.vae_params.iter().filter(|(name, _)| vae_trains(name)).map(|(_, (id, _))| *id).collect();
        let mut attach = Attach {
            factors,
            trainable,
            scale: (LORA_ALPHA / rank as f32) as f64,
            attached: BTreeMap::new(),
            errors: Vec::new(),
        };
        let RefinerParts { vae, unet, prompt_embeds, step, scaling_factor } = refiner.into_parts();
        let vae = vae.apply_reparameterization(&mut attach);
        if let Some(error) = attach.errors.first() {
            return Err(lora_error(&error.0, &error.1));
        }
        let index = ParamIndex { vae: report.vae_params, unet: report.unet_params, adapters: attach.attached, rank };
        Ok(Self {
            weights: RefinerWeights { vae, unet: unet.set_require_grad(true) },
            index,
            prompt_embeds: prompt_embeds.detach(),
            step,
            scaling_factor,
        })
    }

    /// Refines `image` `[batch, 3, h, w]` in [0, 1] as [`Refiner::refine`] does (with `reference` the
    /// reference-view mode), through the unmerged LoRA factors.
    pub fn refine(
        &self,
        image: Tensor<4>,
        reference: Option<Tensor<4>>,
        latent: Latent,
    ) -> Result<Tensor<4>, RefineTrainError> {
        let refiner = Refiner::from_parts(RefinerParts {
            vae: self.weights.vae.clone(),
            unet: self.weights.unet.clone(),
            prompt_embeds: self.prompt_embeds.clone(),
            step: self.step,
            scaling_factor: self.scaling_factor,
        });
        Ok(refiner.refine(image, reference, latent, &mut Trace::default())?)
    }

    /// The refiner on the device without autodiff (for validation and for writing its Difix checkpoint: no
    /// graph is built).
    pub fn valid(&self) -> Self {
        Self { weights: self.weights.valid(), prompt_embeds: self.prompt_embeds.clone().inner(), ..self.clone() }
    }

    /// Replaces the weights with `loaded` (the same modules, as read from a checkpoint, which restores the
    /// parameter ids it was saved with) and follows the ids in the index.
    pub fn with_loaded_weights(mut self, loaded: RefinerWeights) -> Self {
        let renamed: HashMap<ParamId, ParamId> = param_ids(&self.weights).into_iter().zip(param_ids(&loaded)).collect();
        let follow = |id: &mut ParamId| *id = renamed.get(id).copied().unwrap_or(*id);
        for (id, _) in self.index.vae.values_mut().chain(self.index.unet.values_mut()) {
            follow(id);
        }
        for adapter in self.index.adapters.values_mut() {
            follow(&mut adapter.a);
            follow(&mut adapter.b);
        }
        self.weights = loaded;
        self
    }
}

/// Why a LoRA pair cannot become burn's factors.
#[derive(Debug, Clone, PartialEq, Eq)]
enum FactorFault {
    /// One of the two factors is not in the checkpoint.
    Missing,
    /// The factors' shapes do not have the checkpoint's rank.
    Rank { down: Vec<usize>, up: Vec<usize>, rank: usize },
}

impl std::fmt::Display for FactorFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Missing => f.write_str("lora_A or lora_B is missing"),
            Self::Rank { down, up, rank } => write!(f, "lora_A {down:?} and lora_B {up:?} do not have rank {rank}"),
        }
    }
}

/// peft's factors in burn's layout (see the module's doc), checked against the rank.
fn burn_factors(
    pair: LoraPair,
    layout: StoredLayout,
    rank: usize,
    device: &Device,
) -> Result<(Tensor<2>, Tensor<2>), FactorFault> {
    let (Some(down), Some(up)) = (pair.down, pair.up) else {
        return Err(FactorFault::Missing);
    };
    let (out, rest) = (up.shape[0], down.shape[1..].iter().product::<usize>());
    let up_ok = up.shape.len() >= 2 && up.shape[1] == rank && up.shape[2..].iter().all(|&d| d == 1);
    if down.shape.first() != Some(&rank) || !up_ok {
        return Err(FactorFault::Rank { down: down.shape, up: up.shape, rank });
    }
    let tensor =
        |t: &HostTensor, shape: [usize; 2]| Tensor::<2>::from_data(TensorData::new(t.values.clone(), shape), device);
    Ok(match layout {
        StoredLayout::AsFile => (tensor(&up, [out, rank]), tensor(&down, [rank, rest])),
        StoredLayout::Transposed => (tensor(&down, [rank, rest]).transpose(), tensor(&up, [out, rank]).transpose()),
    })
}

/// Attaches the LoRA factors to their weights and freezes every VAE parameter that does not train.
struct Attach {
    factors: HashMap<ParamId, (String, Tensor<2>, Tensor<2>, StoredLayout)>,
    trainable: HashSet<ParamId>,
    scale: f64,
    attached: BTreeMap<String, Adapter>,
    /// `(target, detail)` of factors that do not fit their weight.
    errors: Vec<(String, String)>,
}

impl Reparameterizer for &mut Attach {
    type Reparam = LoraAdapter;

    fn reparameterize<const D: usize>(
        &mut self,
        _path: &str,
        param: Param<Tensor<D>>,
    ) -> (Param<Tensor<D>>, Option<LoraAdapter>) {
        let trains = self.trainable.contains(&param.id);
        let param = param.set_require_grad(trains);
        let Some((target, a, b, layout)) = self.factors.remove(&param.id) else {
            return (param, None);
        };
        let shape = param.dims().to_vec();
        let fits = a.dims()[0] == shape[0] && a.dims()[0] * b.dims()[1] == shape.iter().product::<usize>();
        if !fits {
            let detail = format!("factors {:?} x {:?} do not fit the weight {shape:?}", a.dims(), b.dims());
            self.errors.push((target, detail));
            return (param, None);
        }
        let (a, b) = (Param::from_tensor(a).set_require_grad(true), Param::from_tensor(b).set_require_grad(true));
        self.attached.insert(target, Adapter { a: a.id, b: b.id, layout });
        (param, Some(LoraAdapter { a, b, scale: self.scale }))
    }
}

/// The ids of a module's parameters in visiting order (LoRA factors after their base).
pub fn param_ids<M: Module>(module: &M) -> Vec<ParamId> {
    struct Ids(Vec<ParamId>);
    impl ModuleVisitor for Ids {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.push(param.id);
        }
    }
    let mut ids = Ids(Vec::new());
    module.visit(&mut ids);
    ids.0
}

/// The host values of a module's parameters by id (a LoRA target's base weight, not its effective one).
pub fn param_values<M: Module>(module: &M) -> HashMap<ParamId, TensorData> {
    struct Values(HashMap<ParamId, TensorData>);
    impl ModuleVisitor for Values {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.insert(param.id, param.val().into_data());
        }
    }
    let mut values = Values(HashMap::new());
    module.visit(&mut values);
    values.0
}
