//! Training pairs: a frame with artifacts (the refiner's input) and its ground truth (the loss's target).
//!
//! Images are host `[3, H, W]` RGB in [0, 1], channel-major. Where no reconstruction renders are at hand,
//! [`degrade`] makes the artifacts the refiner removes from a clean image, reproducibly from a seed: ghosting
//! (a blend with a shifted copy, as from misplaced Gaussians), a hole (a dark rectangle, as from
//! disocclusion) and pixel noise. The pairs of a step are a pure function of `(seed, step)`
//! ([`step_indices`]), so a resumed run draws what an uninterrupted one would.

use std::borrow::Cow;
use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};

use crate::error::{PairKind, RefineTrainError};
use dggt_model::safetensors_file::SafetensorsFile;

use crate::pair::unit_range;
pub use crate::pair::{Image, Pair};
use crate::pair_files::PairFiles;

/// Where a run's pairs are: in memory (synthetic pairs), or in pairs files read a pair at a time.
#[derive(Debug, Clone)]
pub enum PairSource {
    InMemory(Vec<Pair>),
    Files(PairFiles),
}

impl PairSource {
    fn len(&self) -> usize {
        match self {
            Self::InMemory(pairs) => pairs.len(),
            Self::Files(files) => files.len(),
        }
    }

    fn get(&self, index: usize) -> Result<Cow<'_, Pair>, RefineTrainError> {
        match self {
            Self::InMemory(pairs) => pairs.get(index).map(Cow::Borrowed).ok_or(RefineTrainError::NoSuchPair {
                kind: PairKind::Any,
                index,
                count: pairs.len(),
            }),
            Self::Files(files) => Ok(Cow::Owned(files.read(index)?.pair)),
        }
    }
}

/// The pairs trained on and those held out for validation: the last `held_out` of a source.
#[derive(Debug, Clone)]
pub struct PairSet {
    source: PairSource,
    held_out: usize,
}

impl PairSet {
    /// `source` with its last `held_out` pairs held out; at least one must be left to train on.
    pub fn new(source: PairSource, held_out: usize) -> Result<Self, RefineTrainError> {
        if held_out >= source.len() {
            return Err(RefineTrainError::Setting {
                setting: "pairs.held_out",
                detail: format!("{held_out} held out of {} pairs leaves none to train on", source.len()),
            });
        }
        Ok(Self { source, held_out })
    }

    pub fn train_len(&self) -> usize {
        self.source.len() - self.held_out
    }

    pub fn held_out_len(&self) -> usize {
        self.held_out
    }

    /// Training pair `index` (of [`Self::train_len`]).
    pub fn train(&self, index: usize) -> Result<Cow<'_, Pair>, RefineTrainError> {
        if index >= self.train_len() {
            let count = self.train_len();
            return Err(RefineTrainError::NoSuchPair { kind: PairKind::Training, index, count });
        }
        self.source.get(index)
    }

    /// Held-out pair `index` (of [`Self::held_out_len`]).
    pub fn held_out(&self, index: usize) -> Result<Cow<'_, Pair>, RefineTrainError> {
        if index >= self.held_out {
            return Err(RefineTrainError::NoSuchPair { kind: PairKind::HeldOut, index, count: self.held_out });
        }
        self.source.get(self.train_len() + index)
    }
}

/// The tensors `names` of a safetensors file (`[3, H, W]` or `[N, 3, H, W]` float32, values in [0, 1]) as
/// images, in that order.
pub fn read_images(path: &Path, names: &[String]) -> Result<Vec<Image>, RefineTrainError> {
    let invalid = |detail: String| RefineTrainError::ImageFile { path: path.into(), detail };
    let mut file = SafetensorsFile::open(path)?;
    let mut images = Vec::new();
    for name in names {
        let tensor = |detail: String| invalid(format!("tensor '{name}': {detail}"));
        let entry = file.entry(name)?;
        if entry.dtype != "F32" {
            return Err(tensor(format!("{}, expected float32", entry.dtype)));
        }
        let shape = entry.shape.clone();
        let (height, width) = match shape.as_slice() {
            [3, h, w] => (*h, *w),
            [_, 3, h, w] => (*h, *w),
            _ => return Err(tensor(format!("shape {shape:?}, expected [3, H, W] or [N, 3, H, W]"))),
        };
        let values = unit_range(file.read_f32(name)?.values, tensor)?;
        let size = 3 * height * width;
        images.extend(values.chunks_exact(size).map(|v| Image { height, width, values: v.to_vec() }));
    }
    if images.is_empty() {
        return Err(invalid("no image tensor named".into()));
    }
    Ok(images)
}

/// `variants` degraded copies of each image (seeds `0..variants` per image), the last `held_out` pairs held out.
pub fn synthetic_pairs(images: &[Image], variants: usize, held_out: usize) -> Result<PairSet, RefineTrainError> {
    let pairs: Vec<Pair> = images
        .iter()
        .enumerate()
        .flat_map(|(i, image)| {
            (0..variants).map(move |v| Pair {
                render: degrade(image, (i * variants + v) as u64),
                target: image.clone(),
                reference: None,
            })
        })
        .collect();
    PairSet::new(PairSource::InMemory(pairs), held_out)
}

/// `image` with ghosting, a hole and noise drawn from `seed` (see the module's doc).
pub fn degrade(image: &Image, seed: u64) -> Image {
    let Image { height, width, ref values } = *image;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let shift = (1 + rng.random_range(0..3usize), rng.random_range(0..3usize));
    let ghost = 0.3 + 0.2 * rng.random::<f32>();
    let hole_h = (height / 4).max(1);
    let hole_w = (width / 4).max(1);
    let hole_y = rng.random_range(0..=height - hole_h);
    let hole_x = rng.random_range(0..=width - hole_w);
    let mut out = values.clone();
    for c in 0..3 {
        for y in 0..height {
            for x in 0..width {
                let at = |yy: usize, xx: usize| values[(c * height + yy) * width + xx];
                let shifted = at(y.saturating_sub(shift.1), x.saturating_sub(shift.0));
                let in_hole = (hole_y..hole_y + hole_h).contains(&y) && (hole_x..hole_x + hole_w).contains(&x);
                let noise = 0.04 * (rng.random::<f32>() - 0.5);
                let value = if in_hole { 0.05 } else { (1.0 - ghost) * at(y, x) + ghost * shifted + noise };
                out[(c * height + y) * width + x] = value.clamp(0.0, 1.0);
            }
        }
    }
    Image { height, width, values: out }
}

/// The indices (into `count` training pairs) of step `step`'s `batch` pairs.
pub fn step_indices(seed: u64, step: u64, batch: usize, count: usize) -> Vec<usize> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ step.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    (0..batch).map(|_| rng.random_range(0..count)).collect()
}

/// The `[N, 3, H, W]` renders, targets and (when every pair has one) references of `pairs` on `device`.
pub fn batch_pairs(
    pairs: &[&Pair],
    device: &Device,
) -> Result<(Tensor<4>, Tensor<4>, Option<Tensor<4>>), RefineTrainError> {
    let render = batch(&pairs.iter().map(|p| &p.render).collect::<Vec<_>>(), device)?;
    let target = batch(&pairs.iter().map(|p| &p.target).collect::<Vec<_>>(), device)?;
    let references: Option<Vec<&Image>> = pairs.iter().map(|p| p.reference.as_ref()).collect();
    let reference = references.map(|r| batch(&r, device)).transpose()?;
    Ok((render, target, reference))
}

/// Images of one size as a `[N, 3, H, W]` tensor on `device`.
pub fn batch(images: &[&Image], device: &Device) -> Result<Tensor<4>, RefineTrainError> {
    let first = images.first().ok_or_else(|| RefineTrainError::Batch("no image".into()))?;
    let (height, width) = (first.height, first.width);
    if let Some(other) = images.iter().find(|i| (i.height, i.width) != (height, width)) {
        let sizes = format!("images of {height}x{width} and {}x{} in one batch", other.height, other.width);
        return Err(RefineTrainError::Batch(sizes));
    }
    let values: Vec<f32> = images.iter().flat_map(|i| i.values.iter().copied()).collect();
    Ok(Tensor::from_data(TensorData::new(values, [images.len(), 3, height, width]), device))
}
