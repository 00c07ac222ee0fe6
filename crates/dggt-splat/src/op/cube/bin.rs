//! Tile binning: which screen tiles each kept footprint touches. [`count_kernel`] counts the intersections
//! per tile list (and fills the culling statistics), the prefix sum (`scan`) turns the counts into list
//! offsets, and [`fill_kernel`] writes one sort entry per intersection, which `sort` then orders.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

/// Tiles `[x0, x1) x [y0, y1)` touched by the box `mean2d ± radius`, clipped to the grid.
#[cube]
pub fn tile_rect(
    mx: f32,
    my: f32,
    rx: u32,
    ry: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
) -> (u32, u32, u32, u32) {
    let size = tile_size as f32;
    let (rxf, ryf) = (rx as f32, ry as f32);
    let (tilesx, tilesy) = (tiles_x as f32, tiles_y as f32);
    let x0 = ((mx - rxf) / size).floor().max(0.0).min(tilesx);
    let x1 = ((mx + rxf) / size).ceil().max(0.0).min(tilesx);
    let y0 = ((my - ryf) / size).floor().max(0.0).min(tilesy);
    let y1 = ((my + ryf) / size).ceil().max(0.0).min(tilesy);
    (x0 as u32, x1 as u32, y0 as u32, y1 as u32)
}

/// Counts tile intersections per tile and fills the statistics rows `[V, 9]` (see `CullStats::to_counts`).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn count_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    tile_counts: &Tensor<Atomic<u32>>,
    stats: &Tensor<Atomic<i32>>,
    count: u32,
    views: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
) {
    let k = ABSOLUTE_POS;
    let count = count as usize;
    if k >= count * (views as usize) {
        terminate!();
    }
    let v = k / count;
    let row = 9 * v;
    stats[row].fetch_add(1i32);
    let reason = reasons[k];
    if reason != 0 {
        stats[row + 1 + reason as usize].fetch_add(1i32);
    } else {
        stats[row + 1].fetch_add(1i32);
        let (x0, x1, y0, y1) =
            tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], tile_size, tiles_x, tiles_y);
        let base = v * (tiles_x * tiles_y) as usize;
        for ty in y0..y1 {
            for tx in x0..x1 {
                tile_counts[base + (ty * tiles_x + tx) as usize].fetch_add(1u32);
            }
        }
        let touched = (x1 - x0) * (y1 - y0);
        stats[row + 8].fetch_add(touched as i32);
    }
}

/// Writes one sort entry per (kept Gaussian, tile it touches) into the list's slice of the intersection
/// buffer, in arrival order: the list index, the Gaussian's depth in that view and its index. The slot within
/// the slice does not matter, since [`bitonic_step_kernel`] orders the entries by all three afterwards.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn fill_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    depths: &Tensor<f32>,
    offsets: &Tensor<u32>,
    cursors: &Tensor<Atomic<u32>>,
    entry_lists: &mut Tensor<u32>,
    entry_depths: &mut Tensor<f32>,
    entry_ids: &mut Tensor<u32>,
    count: u32,
    views: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
) {
    let k = ABSOLUTE_POS;
    let count = count as usize;
    if k >= count * (views as usize) {
        terminate!();
    }
    if reasons[k] == 0 {
        let v = k / count;
        let n = (k % count) as u32;
        let depth = depths[k];
        let (x0, x1, y0, y1) =
            tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], tile_size, tiles_x, tiles_y);
        let base = v * (tiles_x * tiles_y) as usize;
        for ty in y0..y1 {
            for tx in x0..x1 {
                let list = base + (ty * tiles_x + tx) as usize;
                let slot = (offsets[list] + cursors[list].fetch_add(1u32)) as usize;
                entry_lists[slot] = list as u32;
                entry_depths[slot] = depth;
                entry_ids[slot] = n;
            }
        }
    }
}
