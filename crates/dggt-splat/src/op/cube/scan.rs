//! Exclusive prefix sums of `u32` counts of any length, on the device, one cube of [`SCAN_UNITS`] units per
//! tile of [`SCAN_TILE`] values ([`SCAN_ITEMS`] a unit). For `len` values in `t = ⌈len / SCAN_TILE⌉` tiles:
//!
//! 1. [`tile_sums_kernel`] (only when `t > 1`): each cube sums its tile into `sums[tile]` (coalesced loads:
//!    unit `u` reads entries `u, u + SCAN_UNITS, ..` of the tile, then a scan of the units' sums in shared
//!    memory);
//! 2. the `t` tile sums are scanned the same way, recursively, until one tile holds them all;
//! 3. [`tile_prefixes_kernel`]: each cube stages its tile in shared memory (coalesced), each unit scans its
//!    [`SCAN_ITEMS`] consecutive values serially, a Hillis-Steele scan of the units' sums in shared memory gives
//!    each unit its offset, and the tile is written back (coalesced) from the tile's offset.
//!
//! `len` values take `⌈log_2048 len⌉` levels of at most two launches each (one launch when the values fit one
//! tile: 26 M pair counts take 5 launches), the values read twice and written once. Shared memory per cube:
//! the tile (`SCAN_TILE` words, padded by one word in 32 against bank conflicts: 8.25 KiB) and the units' sums
//! (1 KiB), within WebGPU's guaranteed 16 KiB.
//!
//! The kernels run through WGSL (the `wgpu` feature, lavapipe included, which the tests use); barriers sit only
//! in uniform control flow (no early exit: idle cubes and units past `len` mask their loads and stores). The
//! `vulkan` (SPIR-V) feature's shared-memory kernels are checked on a GPU: lavapipe's SPIR-V compiler rejects
//! the shared memory CubeCL emits where Vulkan's explicit workgroup layout is missing.
//!
//! Sums are `u32` and wrap past `2^32`; a difference of two prefixes is still exact while the values between
//! them sum to less than `2^32`.

use burn::backend::DType;
use burn_cubecl::CubeDevice;
use burn_cubecl::cubecl;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::tensor::CubeTensor;

use super::{arg, buffer, cube_launch};

/// Units of a scanning cube.
pub const SCAN_UNITS: u32 = 256;
/// Consecutive values each unit scans serially.
pub const SCAN_ITEMS: u32 = 8;
/// Values one cube scans.
pub const SCAN_TILE: u32 = SCAN_UNITS * SCAN_ITEMS;
/// `log2(SCAN_UNITS)`: steps of the scan of the units' sums.
const SCAN_STEPS: u32 = 8;

/// Where shared-memory word `i` is stored: one word of padding after every 32, so that units reading words
/// 4 or 8 apart hit distinct banks.
#[cube]
pub fn padded(i: usize) -> usize {
    i + (i >> 5)
}

/// Shared words needed for `words` padded words.
pub const fn padded_len(words: u32) -> usize {
    (words + words / 32) as usize
}

/// The index of this cube's tile (cubes may be spread over two dimensions).
#[cube]
pub fn tile_index() -> usize {
    CUBE_POS
}

/// `sums[tile]`: the sum of tile `tile` of `values` (length `len`).
#[cube(launch)]
pub fn tile_sums_kernel(values: &Tensor<u32>, sums: &mut Tensor<u32>, len: u32, tiles: u32) {
    let tile = tile_index();
    let unit = UNIT_POS as usize;
    let base = tile * SCAN_TILE as usize;
    let mut sum = 0u32;
    #[unroll]
    for j in 0..SCAN_ITEMS as usize {
        let i = base + j * SCAN_UNITS as usize + unit;
        if i < len as usize {
            sum += values[i];
        }
    }
    let mut partial = Shared::<[u32]>::new_slice(SCAN_UNITS as usize);
    partial[unit] = sum;
    sync_cube();
    scan_units(&mut partial);
    if unit == 0 && tile < tiles as usize {
        sums[tile] = partial[SCAN_UNITS as usize - 1];
    }
}

/// Stages tile `base..` of `values` in `staged` (padded), zeros past `len`; coalesced.
#[cube]
fn stage_tile(values: &Tensor<u32>, staged: &mut Shared<[u32]>, base: usize, len: u32) {
    #[unroll]
    for j in 0..SCAN_ITEMS as usize {
        let i = j * SCAN_UNITS as usize + UNIT_POS as usize;
        let mut value = 0u32;
        if base + i < len as usize {
            value = values[base + i];
        }
        staged[padded(i)] = value;
    }
}

/// Replaces the unit's [`SCAN_ITEMS`] consecutive staged values by their exclusive prefixes; returns their sum.
#[cube]
fn scan_own_items(staged: &mut Shared<[u32]>) -> u32 {
    let first = UNIT_POS as usize * SCAN_ITEMS as usize;
    let mut running = 0u32;
    #[unroll]
    for k in 0..SCAN_ITEMS as usize {
        let slot = padded(first + k);
        let value = staged[slot];
        staged[slot] = running;
        running += value;
    }
    running
}

/// Inclusive Hillis-Steele scan of `partial` (one value per unit) in place; every unit of the cube calls it.
#[cube]
fn scan_units(partial: &mut Shared<[u32]>) {
    let unit = UNIT_POS as usize;
    let mut offset = 1usize;
    #[unroll]
    for _ in 0..SCAN_STEPS {
        let mut add = 0u32;
        if unit >= offset {
            add = partial[unit - offset];
        }
        sync_cube();
        partial[unit] += add;
        sync_cube();
        offset *= 2;
    }
}

/// Writes the exclusive prefixes of tile `tile` of `values`, starting from `offsets[tile]` (from 0 without
/// `offset_given`); the last tile also writes the total to `prefix[len]`.
#[cube(launch)]
pub fn tile_prefixes_kernel(
    values: &Tensor<u32>,
    offsets: &Tensor<u32>,
    prefix: &mut Tensor<u32>,
    len: u32,
    tiles: u32,
    #[comptime] offset_given: bool,
) {
    let tile = tile_index();
    let unit = UNIT_POS as usize;
    let base = tile * SCAN_TILE as usize;
    let mut staged = Shared::<[u32]>::new_slice(comptime!(padded_len(SCAN_TILE)));
    let mut partial = Shared::<[u32]>::new_slice(SCAN_UNITS as usize);
    stage_tile(values, &mut staged, base, len);
    sync_cube();
    let own = scan_own_items(&mut staged);
    partial[unit] = own;
    sync_cube();
    scan_units(&mut partial);

    let mut tile_offset = 0u32;
    if offset_given && tile < tiles as usize {
        tile_offset = offsets[tile];
    }
    let unit_offset = tile_offset + partial[unit] - own;
    let first = unit * SCAN_ITEMS as usize;
    #[unroll]
    for k in 0..SCAN_ITEMS as usize {
        staged[padded(first + k)] += unit_offset;
    }
    sync_cube();
    #[unroll]
    for j in 0..SCAN_ITEMS as usize {
        let i = j * SCAN_UNITS as usize + unit;
        if base + i < len as usize {
            prefix[base + i] = staged[padded(i)];
        }
    }
    if unit == 0 && tile + 1 == tiles as usize {
        prefix[len as usize] = tile_offset + partial[SCAN_UNITS as usize - 1];
    }
}

/// The exclusive prefix sum of the first `len` values of `values` (`u32`), `len + 1` long: entry `len` is
/// the total.
pub fn exclusive_scan(device: &CubeDevice, values: &CubeTensor, len: usize) -> CubeTensor {
    let client = device.client();
    let prefix = buffer(device, len + 1, DType::U32);
    let tiles = len.div_ceil(SCAN_TILE as usize).max(1);
    let (cubes, dim) = cube_launch(&client, tiles, SCAN_UNITS);
    let offset_given = tiles > 1;
    // One tile starts from 0 and reads no offsets: a placeholder, distinct from `values` (one buffer bound
    // twice in a launch is not portable).
    let offsets = if offset_given {
        let sums = buffer(device, tiles, DType::U32);
        tile_sums_kernel::launch(&client, cubes.clone(), dim, arg(values), arg(&sums), len as u32, tiles as u32);
        exclusive_scan(device, &sums, tiles)
    } else {
        buffer(device, 1, DType::U32)
    };
    tile_prefixes_kernel::launch(
        &client,
        cubes,
        dim,
        arg(values),
        arg(&offsets),
        arg(&prefix),
        len as u32,
        tiles as u32,
        offset_given,
    );
    prefix
}
