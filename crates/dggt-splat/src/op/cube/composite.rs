//! Compositing: each pixel's tile list blended front to back into colour, alpha and depth (expected, or the
//! median: [`DepthStatistic`](crate::DepthStatistic)), with the early stop at the transmittance floor.
//!
//! One cube per tile, one unit per pixel of it. The tile's footprints are staged through shared memory in
//! batches of up to `stage` footprints, each loaded by one unit, so that every footprint is read from global
//! memory once per tile instead of once per pixel; every unit then blends its pixel from shared memory. A
//! shared count of the units that are done (outside the image, or stopped at the transmittance floor) ends the
//! walk of the whole cube once it reaches the cube's size. Loop bounds that gate barriers are read with
//! `workgroup_uniform_load`, so that WGSL's uniformity rules hold.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use super::args::{BlendInputs, Grid};
use super::stage::{FootprintStage, footprint_at, load_footprint};
use crate::constants::{MEDIAN_TRANSMITTANCE, MIN_DEPTH_ALPHA, MIN_TRANSMITTANCE};

/// The range `[start, end)` of the cube's tile list, the same value in every unit of the cube.
#[cube]
pub fn tile_range(ranges: &Tensor<u32>, list: usize) -> (u32, u32) {
    let mut bounds = Shared::<[u32]>::new_slice(2usize);
    if UNIT_POS == 0 {
        bounds[0] = ranges[2 * list];
        bounds[1] = ranges[2 * list + 1];
    }
    let start = workgroup_uniform_load(&bounds[0]);
    let end = workgroup_uniform_load(&bounds[1]);
    (start, end)
}

/// Where a compositing unit works, the same in both passes: one cube per tile (`CUBE_POS_X` its column,
/// `first_row + CUBE_POS_Y` its row, `CUBE_POS_Z` the view within the batch of views starting at `first_view`),
/// one unit per pixel of it.
#[derive(CubeType)]
pub struct TilePixel {
    /// Where the view's (view, Gaussian) pairs start: `v · N`.
    pub base: usize,
    /// The pixel's index `(v · H + y) · W + x`, valid only `inside`.
    pub pixel: usize,
    /// Whether the pixel lies in the image (the last row and column of tiles can overhang it).
    pub inside: bool,
    /// The pixel's centre, x.
    pub px: f32,
    /// The pixel's centre, y.
    pub py: f32,
    /// Start of the tile list's range of the batch's sorted ids.
    pub start: u32,
    /// End (exclusive) of the tile list's range.
    pub end: u32,
}

/// The unit's [`TilePixel`]; every unit of the cube calls it (it reads the list range through shared memory).
#[cube]
pub fn tile_pixel(grid: &Grid, ranges: &Tensor<u32>, first_view: u32, first_row: u32) -> TilePixel {
    let batch_view = CUBE_POS_Z as usize;
    let v = first_view as usize + batch_view;
    let tile_row = first_row + CUBE_POS_Y;
    let x = CUBE_POS_X * grid.tile_size + UNIT_POS_X;
    let y = tile_row * grid.tile_size + UNIT_POS_Y;
    let tiles = (grid.tiles_x * grid.tiles_y) as usize;
    let list = batch_view * tiles + (tile_row * grid.tiles_x + CUBE_POS_X) as usize;
    let (start, end) = tile_range(ranges, list);
    TilePixel {
        base: v * grid.count as usize,
        pixel: (v * grid.height as usize + y as usize) * grid.width as usize + x as usize,
        inside: x < grid.width && y < grid.height,
        px: x as f32 + 0.5,
        py: y as f32 + 0.5,
        start,
        end,
    }
}

/// Front-to-back compositing, one cube per tile and one unit per pixel ([`TilePixel`]), footprints staged
/// `stage` at a time.
///
/// Writes the packed image `[V, H, W, K + 2]` (colours, alpha, depth: the median where `median_depth`, else the
/// expected), the final transmittance and the list end (entries of the list up to the last one blended) per pixel.
#[cube(launch)]
// The median's tests are runtime conditions inside comptime ones, which the expansion removes whole when off.
#[allow(clippy::too_many_arguments, clippy::collapsible_if)]
pub fn composite_kernel(
    inputs: &BlendInputs,
    images: &mut Tensor<f32>,
    transmittances: &mut Tensor<f32>,
    list_ends: &mut Tensor<u32>,
    grid: Grid,
    first_view: u32,
    first_row: u32,
    #[comptime] stage: u32,
    #[comptime] channels: usize,
    #[comptime] median_depth: bool,
) {
    let units = CUBE_DIM;
    let slots = comptime!(stage as usize);
    let t = tile_pixel(&grid, &inputs.ranges, first_view, first_row);
    let (start, end) = (t.start, t.end);

    let mut staged = FootprintStage::new(slots, channels);
    let finished = Shared::<[Atomic<u32>]>::new_slice(1usize);
    if UNIT_POS == 0 {
        finished[0].store(0u32);
    }
    sync_cube();

    let mut done = !t.inside;
    if done {
        finished[0].fetch_add(1u32);
    }
    let mut accumulated = Array::<f32>::new(channels);
    for ch in 0..channels {
        accumulated[ch] = 0.0;
    }
    let mut depth = 0.0f32;
    // Zero until the transmittance first falls to one half (a drawn footprint lies beyond the near plane, z > 0).
    let mut median = 0.0f32;
    let mut transmittance = 1.0f32;
    let mut last = 0u32;
    let mut batch_start = start;
    loop {
        // The barrier of the uniform load also keeps the previous batch in place until every unit used it.
        let finished_units = workgroup_uniform_load_atomic(&finished[0]);
        if batch_start >= end || finished_units == units {
            break;
        }
        let slot = UNIT_POS as usize;
        let entry = batch_start + UNIT_POS;
        if UNIT_POS < stage && entry < end {
            let e = entry as usize;
            load_footprint(&mut staged, slot, inputs, e, t.base, grid.per_view, channels);
        }
        sync_cube();
        let batch = (end - batch_start).min(stage);
        if !done {
            for i in 0..batch {
                let s = i as usize;
                let f = footprint_at(&staged, s, t.px, t.py);
                let alpha = f.alpha;
                if f.visible {
                    let next = transmittance * (1.0 - alpha);
                    if next <= MIN_TRANSMITTANCE {
                        done = true;
                        break;
                    }
                    let weight = alpha * transmittance;
                    for ch in 0..channels {
                        accumulated[ch] += staged.colors[channels * s + ch] * weight;
                    }
                    depth += staged.depths[s] * weight;
                    if comptime!(median_depth) {
                        if median == 0.0 && next <= MEDIAN_TRANSMITTANCE {
                            median = staged.depths[s];
                        }
                    }
                    transmittance = next;
                    last = batch_start + i - start + 1;
                }
            }
            if done {
                finished[0].fetch_add(1u32);
            }
        }
        batch_start += stage;
    }
    if t.inside {
        let pixel = t.pixel;
        let alpha = 1.0 - transmittance;
        let out = pixel * (channels + 2);
        for ch in 0..channels {
            images[out + ch] = accumulated[ch] + transmittance * inputs.background[ch];
        }
        images[out + channels] = alpha;
        let expected = depth / alpha.max(MIN_DEPTH_ALPHA);
        images[out + channels + 1] = expected;
        if comptime!(median_depth) {
            if median > 0.0 {
                images[out + channels + 1] = median;
            }
        }
        transmittances[pixel] = transmittance;
        list_ends[pixel] = last;
    }
}
