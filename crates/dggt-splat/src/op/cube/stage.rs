//! A tile's footprints staged in shared memory by the compositing kernels: each unit of the tile's cube loads
//! one list entry's footprint (Gaussian index, 2D mean, conic, opacity, depth, colours) into its slot, then
//! every unit reads the whole stage from there instead of from global memory, and evaluates each staged
//! footprint at its pixel with [`footprint_at`].

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use super::args::BlendInputs;
use crate::constants::{ALPHA_THRESHOLD, MAX_ALPHA};

/// Where one list entry's values sit in global memory.
#[derive(CubeType)]
pub struct EntryIndex {
    /// Index of the Gaussian.
    pub id: usize,
    /// Index of the (view, Gaussian) pair.
    pub pair: usize,
    /// Where its opacity is: `id` (shared opacities) or `pair` (per view).
    pub opacity_slot: usize,
}

/// The entry at `entry` of the sorted ids, for the view whose pairs start at `base` (`base = v * count`).
#[cube]
pub fn entry_index(ids: &Tensor<u32>, entry: usize, base: usize, per_view: u32) -> EntryIndex {
    let id = ids[entry] as usize;
    let pair = base + id;
    let mut opacity_slot = id;
    if per_view == 1 {
        opacity_slot = pair;
    }
    EntryIndex { id, pair, opacity_slot }
}

/// The footprint of each staged entry, slot by slot (`2`, `3` and `K` values a slot for the means, conics and
/// colours).
#[derive(CubeType)]
pub struct FootprintStage {
    pub ids: Shared<[u32]>,
    pub means: Shared<[f32]>,
    pub conics: Shared<[f32]>,
    pub opacities: Shared<[f32]>,
    pub depths: Shared<[f32]>,
    pub colors: Shared<[f32]>,
}

#[cube]
impl FootprintStage {
    /// Room for `slots` footprints of `channels` colours.
    pub fn new(#[comptime] slots: usize, #[comptime] channels: usize) -> FootprintStage {
        FootprintStage {
            ids: Shared::<[u32]>::new_slice(slots),
            means: Shared::<[f32]>::new_slice(2 * slots),
            conics: Shared::<[f32]>::new_slice(3 * slots),
            opacities: Shared::<[f32]>::new_slice(slots),
            depths: Shared::<[f32]>::new_slice(slots),
            colors: Shared::<[f32]>::new_slice(channels * slots),
        }
    }
}

/// Copies list entry `entry` (of the view whose pairs start at `base`) into `slot` of `stage`.
#[cube]
pub fn load_footprint(
    stage: &mut FootprintStage,
    slot: usize,
    inputs: &BlendInputs,
    entry: usize,
    base: usize,
    per_view: u32,
    #[comptime] channels: usize,
) {
    let f = entry_index(&inputs.ids, entry, base, per_view);
    stage.ids[slot] = f.id as u32;
    stage.means[2 * slot] = inputs.means2d[2 * f.pair];
    stage.means[2 * slot + 1] = inputs.means2d[2 * f.pair + 1];
    stage.conics[3 * slot] = inputs.conics[3 * f.pair];
    stage.conics[3 * slot + 1] = inputs.conics[3 * f.pair + 1];
    stage.conics[3 * slot + 2] = inputs.conics[3 * f.pair + 2];
    stage.opacities[slot] = inputs.opacities[f.opacity_slot];
    stage.depths[slot] = inputs.depths[f.pair];
    for ch in 0..channels {
        stage.colors[channels * slot + ch] = inputs.colors[f.id * channels + ch];
    }
}

/// A staged footprint evaluated at a pixel centre: the offset to its mean, its conic `(a, b, c)`, the falloff
/// `exp(-sigma)` of its Gaussian there, the opacity times the falloff (`raw`), that clamped to [`MAX_ALPHA`]
/// (`alpha`), and whether the pixel blends it at all (`visible`: `sigma` a non-negative number and `alpha` at
/// least [`ALPHA_THRESHOLD`]). Both compositing passes blend from it, so that they agree on every value.
#[derive(CubeType)]
pub struct PixelFootprint {
    pub dx: f32,
    pub dy: f32,
    pub a: f32,
    pub b: f32,
    pub c: f32,
    pub falloff: f32,
    pub raw: f32,
    pub alpha: f32,
    pub visible: bool,
}

/// The footprint staged in `slot` at the pixel centre `(px, py)`.
#[cube]
pub fn footprint_at(stage: &FootprintStage, slot: usize, px: f32, py: f32) -> PixelFootprint {
    let dx = stage.means[2 * slot] - px;
    let dy = stage.means[2 * slot + 1] - py;
    let (a, b, c) = (stage.conics[3 * slot], stage.conics[3 * slot + 1], stage.conics[3 * slot + 2]);
    let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
    let falloff = (-sigma).exp();
    let raw = stage.opacities[slot] * falloff;
    let alpha = raw.min(MAX_ALPHA);
    let visible = !(sigma.is_nan() || sigma < 0.0 || alpha < ALPHA_THRESHOLD);
    PixelFootprint { dx, dy, a, b, c, falloff, raw, alpha, visible }
}
