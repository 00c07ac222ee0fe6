//! Applying a refiner checkpoint's VAE entries to the base VAE's tensors: skip convolutions and other
//! plain weights replace or extend the base, and every LoRA pair is merged into its target's weight,
//! `W + (alpha / r) B A` (for a convolution `B` is 1x1 and `A` has the target's kernel, stride and padding,
//! so the merged kernel is exactly equivalent).
//!
//! peft names a wrapped module's own weight `<module>.base_layer.weight` and its pair
//! `<module>.lora_A.<adapter>.weight` / `<module>.lora_B.<adapter>.weight`. `alpha` is peft's default, 8.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::RefineError;
use crate::weights::{HostTensor, NamedTensors};

/// peft's default `lora_alpha`, which Difix's configuration keeps.
pub const LORA_ALPHA: f32 = 8.0;

/// The adapter name of Difix's VAE LoRA in peft's tensor names.
pub const LORA_ADAPTER: &str = "vae_skip";

/// One module's LoRA factors as a checkpoint holds them: `down` (peft's `lora_A`, `[rank, rest...]`) and `up`
/// (`lora_B`, `[out, rank, (1, 1)]`); `None` where the checkpoint lacks one.
#[derive(Debug, Clone, Default)]
pub struct LoraPair {
    pub down: Option<HostTensor>,
    pub up: Option<HostTensor>,
}

/// peft's names of `module`'s LoRA factors: `[lora_A, lora_B]`.
pub fn lora_names(module: &str) -> [String; 2] {
    [format!("{module}.lora_A.{LORA_ADAPTER}.weight"), format!("{module}.lora_B.{LORA_ADAPTER}.weight")]
}

/// Splits a checkpoint's VAE tensors into plain tensors, by VAE name (a wrapped module's
/// `.base_layer.` dropped), and LoRA pairs, by module.
pub fn split_lora_pairs(checkpoint: NamedTensors) -> (NamedTensors, BTreeMap<String, LoraPair>) {
    let mut pairs: BTreeMap<String, LoraPair> = BTreeMap::new();
    let mut plain = NamedTensors::new();
    for (name, tensor) in checkpoint {
        let half = |marker: &str| name.split_once(marker).map(|(module, _)| module.to_string());
        if let Some(module) = half(".lora_A.") {
            pairs.entry(module).or_default().down = Some(tensor);
        } else if let Some(module) = half(".lora_B.") {
            pairs.entry(module).or_default().up = Some(tensor);
        } else {
            plain.insert(name.replace(".base_layer.", "."), tensor);
        }
    }
    (plain, pairs)
}

/// What the checkpoint changed in the VAE.
#[derive(Debug, Clone, Default)]
pub struct VaeOverlay {
    /// Plain tensors taken from the checkpoint (the skip convolutions), by VAE name.
    pub replaced: Vec<String>,
    /// Modules whose weight received a merged LoRA update.
    pub merged: Vec<String>,
}

/// Applies the checkpoint's `vae` tensors to `base` (see the module's doc). `targets` must each have a LoRA
/// pair, and every pair must belong to a target.
pub fn apply_vae_overlay(
    base: &mut NamedTensors,
    checkpoint: NamedTensors,
    targets: &[String],
    rank: usize,
    path: &Path,
) -> Result<VaeOverlay, RefineError> {
    apply_vae_overlay_scaled(base, checkpoint, targets, rank, LORA_ALPHA, path)
}

/// [`apply_vae_overlay`] with the LoRA scale `alpha / rank` of a given `alpha`.
pub fn apply_vae_overlay_scaled(
    base: &mut NamedTensors,
    checkpoint: NamedTensors,
    targets: &[String],
    rank: usize,
    alpha: f32,
    path: &Path,
) -> Result<VaeOverlay, RefineError> {
    let lora_error = |module: &str, message: String| RefineError::Lora {
        path: path.display().to_string(),
        module: module.to_string(),
        message,
    };
    let (plain, mut pairs) = split_lora_pairs(checkpoint);
    let mut overlay = VaeOverlay::default();
    for (name, tensor) in plain {
        overlay.replaced.push(name.clone());
        base.insert(name, tensor);
    }
    let scale = alpha / rank as f32;
    for target in targets {
        let Some(LoraPair { down: Some(down), up: Some(up) }) = pairs.remove(target) else {
            return Err(lora_error(target, "lora_A or lora_B is missing from state_dict_vae".into()));
        };
        let weight_name = format!("{target}.weight");
        let weight = base.get_mut(&weight_name).ok_or_else(|| RefineError::MissingTensor {
            path: path.display().to_string(),
            name: weight_name.clone(),
        })?;
        merge(weight, &down, &up, rank, scale).map_err(|mismatch| lora_error(target, mismatch.to_string()))?;
        overlay.merged.push(target.clone());
    }
    if let Some(stray) = pairs.keys().next() {
        return Err(lora_error(stray, "has a LoRA pair but is not in vae_lora_target_modules".into()));
    }
    Ok(overlay)
}

/// A LoRA pair whose shapes do not fit the weight it is merged into.
#[derive(Debug, thiserror::Error)]
#[error("lora_A {down:?} and lora_B {up:?} do not fit the weight {weight:?} at rank {rank}")]
struct PairMismatch {
    down: Vec<usize>,
    up: Vec<usize>,
    weight: Vec<usize>,
    rank: usize,
}

/// `weight += scale * up @ down`, `weight`: `[out, rest...]`, `down`: `[rank, rest...]`,
/// `up`: `[out, rank, (1, 1)]`.
fn merge(
    weight: &mut HostTensor,
    down: &HostTensor,
    up: &HostTensor,
    rank: usize,
    scale: f32,
) -> Result<(), PairMismatch> {
    let out = weight.shape[0];
    let rest = &weight.shape[1..];
    let up_ok = up.shape.len() >= 2 && up.shape[..2] == [out, rank] && up.shape[2..].iter().all(|&d| d == 1);
    if down.shape[0] != rank || &down.shape[1..] != rest || !up_ok {
        let (down, up, weight) = (down.shape.clone(), up.shape.clone(), weight.shape.clone());
        return Err(PairMismatch { down, up, weight, rank });
    }
    let inner: usize = rest.iter().product();
    for o in 0..out {
        let row = &mut weight.values[o * inner..(o + 1) * inner];
        for r in 0..rank {
            let coefficient = scale * up.values[o * rank + r];
            let down_row = &down.values[r * inner..(r + 1) * inner];
            row.iter_mut().zip(down_row).for_each(|(w, d)| *w += coefficient * d);
        }
    }
    Ok(())
}
