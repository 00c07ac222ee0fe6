//! A tile's footprints staged in shared memory by the compositing kernels: each unit of the tile's cube loads
//! one list entry's footprint (Gaussian index, 2D mean, conic, opacity, depth, colours) into its slot, then
//! every unit reads the whole stage from there instead of from global memory.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

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
#[allow(clippy::too_many_arguments)]
pub fn load_footprint(
    stage: &mut FootprintStage,
    slot: usize,
    ids: &Tensor<u32>,
    means2d: &Tensor<f32>,
    conics: &Tensor<f32>,
    depths: &Tensor<f32>,
    opacities: &Tensor<f32>,
    colors: &Tensor<f32>,
    entry: usize,
    base: usize,
    per_view: u32,
    #[comptime] channels: usize,
) {
    let f = entry_index(ids, entry, base, per_view);
    stage.ids[slot] = f.id as u32;
    stage.means[2 * slot] = means2d[2 * f.pair];
    stage.means[2 * slot + 1] = means2d[2 * f.pair + 1];
    stage.conics[3 * slot] = conics[3 * f.pair];
    stage.conics[3 * slot + 1] = conics[3 * f.pair + 1];
    stage.conics[3 * slot + 2] = conics[3 * f.pair + 2];
    stage.opacities[slot] = opacities[f.opacity_slot];
    stage.depths[slot] = depths[f.pair];
    for ch in 0..channels {
        stage.colors[channels * slot + ch] = colors[f.id * channels + ch];
    }
}
