//! Tile binning: which screen tiles each kept footprint touches. [`count_kernel`] counts the tiles of every
//! (view, Gaussian) pair (and fills the culling statistics), the prefix sum (`scan`) turns the counts into
//! each pair's offset, [`fill_kernel`] writes one sort entry per intersection at those offsets (in pair order,
//! no atomics), `radix` sorts them by (list, depth), and [`ranges_kernel`] finds each list's range.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use super::args::Grid;

/// Tiles `[x0, x1) x [y0, y1)` touched by the box `mean2d ± radius`, clipped to the grid.
#[cube]
pub fn tile_rect(mx: f32, my: f32, rx: u32, ry: u32, grid: &Grid) -> (u32, u32, u32, u32) {
    let size = grid.tile_size as f32;
    let (rxf, ryf) = (rx as f32, ry as f32);
    let (tilesx, tilesy) = (grid.tiles_x as f32, grid.tiles_y as f32);
    let x0 = ((mx - rxf) / size).floor().max(0.0).min(tilesx);
    let x1 = ((mx + rxf) / size).ceil().max(0.0).min(tilesx);
    let y0 = ((my - ryf) / size).floor().max(0.0).min(tilesy);
    let y1 = ((my + ryf) / size).ceil().max(0.0).min(tilesy);
    (x0 as u32, x1 as u32, y0 as u32, y1 as u32)
}

/// `[y0, y1)` clipped to the tile rows `[first_row, end_row)`, empty (`y0 == y1`) when they do not meet.
#[cube]
fn clip_rows(y0: u32, y1: u32, first_row: u32, end_row: u32) -> (u32, u32) {
    let low = y0.max(first_row);
    let high = y1.min(end_row).max(low);
    (low, high)
}

/// Counts the tiles each (view, Gaussian) pair touches into `pair_counts` (zero when culled) and fills the
/// statistics rows `[V, 9]` (see `CullStats::to_counts`).
#[cube(launch)]
pub fn count_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    pair_counts: &mut Tensor<u32>,
    stats: &Tensor<Atomic<i32>>,
    grid: Grid,
) {
    let k = ABSOLUTE_POS;
    let count = grid.count as usize;
    if k >= count * (grid.views as usize) {
        terminate!();
    }
    let v = k / count;
    let row = 9 * v;
    stats[row].fetch_add(1i32);
    let reason = reasons[k];
    let mut touched = 0u32;
    if reason != 0 {
        stats[row + 1 + reason as usize].fetch_add(1i32);
    } else {
        stats[row + 1].fetch_add(1i32);
        let (x0, x1, y0, y1) = tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], &grid);
        touched = (x1 - x0) * (y1 - y0);
        stats[row + 8].fetch_add(touched as i32);
    }
    pair_counts[k] = touched;
}

/// `row_counts[ty]` (zeroed first): the intersections of view `view` in each tile row, which plan its bands.
#[cube(launch)]
pub fn row_counts_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    row_counts: &Tensor<Atomic<u32>>,
    grid: Grid,
    view: u32,
) {
    let count = grid.count as usize;
    let k = view as usize * count + ABSOLUTE_POS;
    if ABSOLUTE_POS >= count {
        terminate!();
    }
    if reasons[k] == 0 {
        let (x0, x1, y0, y1) = tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], &grid);
        for ty in y0..y1 {
            row_counts[ty as usize].fetch_add(x1 - x0);
        }
    }
}

/// A band of one view's tile rows: `pair_counts[k]` the tiles within rows `[first_row, end_row)` of pair `k`
/// of view `view`, zero for every other pair (so that the scan of the counts starts the view's entries at 0).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn band_count_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    pair_counts: &mut Tensor<u32>,
    grid: Grid,
    view: u32,
    first_row: u32,
    end_row: u32,
) {
    let k = ABSOLUTE_POS;
    let count = grid.count as usize;
    if k >= count * (grid.views as usize) {
        terminate!();
    }
    let mut touched = 0u32;
    if k / count == view as usize && reasons[k] == 0 {
        let (x0, x1, y0, y1) = tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], &grid);
        let (low, high) = clip_rows(y0, y1, first_row, end_row);
        touched = (x1 - x0) * (high - low);
    }
    pair_counts[k] = touched;
}

/// `view_starts[v] = pair_offsets[v · count]` for `v` in `0..=views`: where each view's intersections start
/// (entry `views` is the total), the only values read back to size the intersection buffers.
#[cube(launch)]
pub fn view_starts_kernel(pair_offsets: &Tensor<u32>, view_starts: &mut Tensor<u32>, grid: Grid) {
    let v = ABSOLUTE_POS;
    if v <= grid.views as usize {
        view_starts[v] = pair_offsets[v * grid.count as usize];
    }
}

/// Writes the sort entries of the views `first_view..first_view + batch_views` (the pairs `k` from
/// `first_view · count`) in the tile rows `[first_row, end_row)`, each pair at its own offset
/// `pair_offsets[k] - base` in pair order, its tiles in row-major order: the list `(v - first_view) · tiles +
/// tile`, the depth's `f32` bits (positive, so they order as unsigned integers) and the Gaussian index.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn fill_kernel(
    means2d: &Tensor<f32>,
    radii: &Tensor<u32>,
    reasons: &Tensor<u32>,
    depths: &Tensor<f32>,
    pair_offsets: &Tensor<u32>,
    entry_lists: &mut Tensor<u32>,
    entry_depths: &mut Tensor<u32>,
    entry_ids: &mut Tensor<u32>,
    grid: Grid,
    first_view: u32,
    batch_views: u32,
    base: u32,
    first_row: u32,
    end_row: u32,
) {
    let local = ABSOLUTE_POS;
    let count = grid.count as usize;
    if local >= count * (batch_views as usize) {
        terminate!();
    }
    let k = first_view as usize * count + local;
    if reasons[k] == 0 {
        let list_base = (local / count) as u32 * (grid.tiles_x * grid.tiles_y);
        let n = (k % count) as u32;
        let depth = depths[k].to_bits();
        let (x0, x1, y0, y1) = tile_rect(means2d[2 * k], means2d[2 * k + 1], radii[2 * k], radii[2 * k + 1], &grid);
        let (low, high) = clip_rows(y0, y1, first_row, end_row);
        let mut slot = (pair_offsets[k] - base) as usize;
        for ty in low..high {
            for tx in x0..x1 {
                entry_lists[slot] = list_base + ty * grid.tiles_x + tx;
                entry_depths[slot] = depth;
                entry_ids[slot] = n;
                slot += 1;
            }
        }
    }
}

/// Each list's range `[ranges[2 l], ranges[2 l + 1])` of the sorted entries, from the list boundaries
/// (`ranges` zeroed first: an empty list keeps `[0, 0)`).
#[cube(launch)]
pub fn ranges_kernel(entry_lists: &Tensor<u32>, ranges: &mut Tensor<u32>, len: u32) {
    let i = ABSOLUTE_POS;
    let len = len as usize;
    if i >= len {
        terminate!();
    }
    let list = entry_lists[i];
    // Neighbour indices kept in range: both sides of `||` may be evaluated.
    let mut previous = i;
    if i > 0 {
        previous = i - 1;
    }
    let mut next = i;
    if i + 1 < len {
        next = i + 1;
    }
    if previous == i || entry_lists[previous] != list {
        ranges[2 * list as usize] = i as u32;
    }
    if next == i || entry_lists[next] != list {
        ranges[2 * list as usize + 1] = i as u32 + 1;
    }
}
