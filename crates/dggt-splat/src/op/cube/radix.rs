//! A stable least-significant-digit radix sort of `u32` keys with `u32` payloads, [`RADIX_BITS`] bits a pass.
//!
//! A pass over digit `shift..shift + RADIX_BITS`, for `len` entries split into `t` tiles of [`SORT_TILE`], one
//! cube of [`SORT_UNITS`] units per tile:
//!
//! 1. [`tile_histogram_kernel`]: each cube counts its tile's entries per digit, written digit-major
//!    (`histogram[digit · t + tile]`), so that
//! 2. one exclusive scan of the whole histogram gives every (digit, tile) its first output slot;
//! 3. [`tile_scatter_kernel`]: each cube ranks its tile's entries (below) and writes them to their slots.
//!
//! Both kernels stage the tile's keys in shared memory with coalesced loads (unit `u` reads entries
//! `u, u + SORT_UNITS, ..` of the tile), then rank them the same way: each unit owns [`SORT_ITEMS`]
//! consecutive entries and counts their digits (two 16-bit counts a word), and a scan of those counts over the
//! units in shared memory (segments of units scanned serially, then the segments' sums) gives each unit, per
//! digit, how many entries of that digit precede its own in the tile, and the tile's digit totals. The scatter
//! then places each entry at its tile-local sorted position (its digit's start in the tile plus its rank) and
//! writes the tile in that order, so that neighbouring units write neighbouring slots of a digit's range.
//! Entries with equal digits keep their input order, within a tile and across tiles: the sort is stable. No
//! atomics: the result does not depend on scheduling, and matches a host stable sort bit for bit.
//!
//! Shared memory per cube: the keys (1 056 words with padding), the units' counts (2 112 words, reused for the
//! sorted positions' sources), the segments' sums (256) and 40 words of digit totals and starts: 13.5 KiB,
//! within WebGPU's guaranteed 16 KiB. The histogram holds `16 / SORT_TILE` counts per entry. A sort of `N`
//! entries launches, per pass, the histogram, its scan (`N / 64` counts: one launch up to `2^17` entries, three
//! up to `2^28`) and the scatter: 5 launches a pass at `N = 10^8`. The scatter writes each digit's entries to
//! consecutive slots but gathers their payloads from within the tile (4 KiB of each).
//!
//! The kernels run through WGSL (the `wgpu` feature, lavapipe included, which the tests use), barriers only in
//! uniform control flow; the `vulkan` (SPIR-V) feature's shared-memory kernels are checked on a GPU (lavapipe's
//! SPIR-V compiler rejects them).

use burn::backend::DType;
use burn_cubecl::CubeDevice;
use burn_cubecl::cubecl;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::tensor::CubeTensor;

use super::scan::{exclusive_scan, padded, padded_len, tile_index};
use super::{arg, buffer, cube_launch};

/// Bits of the key sorted per pass.
pub const RADIX_BITS: u32 = 4;
/// Distinct digits of a pass.
const DIGITS: usize = 1 << RADIX_BITS;
/// Words of packed per-digit counts: two 16-bit counts a word.
const WORDS: usize = DIGITS / 2;
/// Units of a sorting cube.
pub const SORT_UNITS: u32 = 256;
/// Consecutive entries of the tile each unit ranks.
pub const SORT_ITEMS: u32 = 4;
/// Entries one cube sorts.
pub const SORT_TILE: u32 = SORT_UNITS * SORT_ITEMS;
/// Segments of units a row of counts is split into for its scan: one unit per (word, segment).
const SEGMENTS: usize = SORT_UNITS as usize / WORDS;
/// Units per segment.
const SEGMENT_UNITS: usize = SORT_UNITS as usize / SEGMENTS;

/// The digit of `key` at `shift`.
#[cube]
fn digit(key: u32, shift: u32) -> usize {
    ((key >> shift) & (DIGITS as u32 - 1)) as usize
}

/// The bit shift of digit `d`'s 16-bit count in its word.
#[cube]
fn half_shift(d: usize) -> u32 {
    (d as u32 & 1) * 16
}

/// Digit `d`'s count in a packed word.
#[cube]
fn unpack(word: u32, d: usize) -> u32 {
    (word >> half_shift(d)) & 0xFFFF
}

/// A tile's keys and their digit counts, in shared memory.
#[derive(CubeType)]
pub struct TileDigits {
    /// The tile's keys, padded (see [`padded`]).
    pub keys: Shared<[u32]>,
    /// `counts[padded(word · SORT_UNITS + unit)]`: the unit's packed digit counts, then their exclusive prefix
    /// within the unit's segment; in the scatter, then, the tile index of the entry at each sorted position.
    pub counts: Shared<[u32]>,
    /// `segments[word · SEGMENTS + segment]`: the exclusive prefix of the segments' sums in their row.
    pub segments: Shared<[u32]>,
    /// `totals[word]`: the tile's packed digit counts.
    pub totals: Shared<[u32]>,
}

/// Entries of the tile at `base` below `len`.
#[cube]
fn valid_entries(base: usize, len: u32) -> usize {
    let mut valid = 0usize;
    if base < len as usize {
        valid = (len as usize - base).min(SORT_TILE as usize);
    }
    valid
}

/// Stages the tile's keys and counts their digits at `shift`: afterwards each unit's exclusive prefix per
/// digit is [`unit_prefix`], and the tile's counts are in `totals`. Every unit of the cube calls it.
#[cube]
fn count_tile(keys: &Tensor<u32>, base: usize, valid: usize, shift: u32) -> TileDigits {
    let mut t = TileDigits {
        keys: Shared::<[u32]>::new_slice(comptime!(padded_len(SORT_TILE))),
        counts: Shared::<[u32]>::new_slice(comptime!(padded_len(WORDS as u32 * SORT_UNITS))),
        segments: Shared::<[u32]>::new_slice(WORDS * SEGMENTS),
        totals: Shared::<[u32]>::new_slice(WORDS),
    };
    #[unroll]
    for j in 0..SORT_ITEMS as usize {
        let i = j * SORT_UNITS as usize + UNIT_POS as usize;
        if i < valid {
            t.keys[padded(i)] = keys[base + i];
        }
    }
    sync_cube();
    count_own(&mut t, valid, shift);
    sync_cube();
    scan_segments(&mut t);
    sync_cube();
    scan_rows(&mut t);
    sync_cube();
    t
}

/// Writes the packed digit counts of the unit's own entries to `counts`.
#[cube]
fn count_own(t: &mut TileDigits, valid: usize, shift: u32) {
    let unit = UNIT_POS as usize;
    let mut packed = Array::<u32>::new(WORDS);
    #[unroll]
    for w in 0..WORDS {
        packed[w] = 0;
    }
    #[unroll]
    for k in 0..SORT_ITEMS as usize {
        let i = unit * SORT_ITEMS as usize + k;
        if i < valid {
            let d = digit(t.keys[padded(i)], shift);
            packed[d / 2] += 1u32 << half_shift(d);
        }
    }
    #[unroll]
    for w in 0..WORDS {
        t.counts[padded(w * SORT_UNITS as usize + unit)] = packed[w];
    }
}

/// Each unit scans one segment of one row of `counts` serially (exclusive) and writes the segment's sum.
#[cube]
fn scan_segments(t: &mut TileDigits) {
    let row = UNIT_POS as usize / SEGMENTS;
    let segment = UNIT_POS as usize % SEGMENTS;
    let first = row * SORT_UNITS as usize + segment * SEGMENT_UNITS;
    let mut running = 0u32;
    #[unroll]
    for k in 0..SEGMENT_UNITS {
        let slot = padded(first + k);
        let count = t.counts[slot];
        t.counts[slot] = running;
        running += count;
    }
    t.segments[row * SEGMENTS + segment] = running;
}

/// Unit `w < WORDS` scans row `w`'s segment sums serially (exclusive) and writes the row's total.
#[cube]
fn scan_rows(t: &mut TileDigits) {
    let row = UNIT_POS as usize;
    if row < WORDS {
        let mut running = 0u32;
        for s in 0..SEGMENTS {
            let sum = t.segments[row * SEGMENTS + s];
            t.segments[row * SEGMENTS + s] = running;
            running += sum;
        }
        t.totals[row] = running;
    }
}

/// The unit's packed exclusive prefix in the tile for word `w` (digits `2w` and `2w + 1`), from a tile's
/// `counts` and `segments`.
#[cube]
fn unit_prefix(counts: &Shared<[u32]>, segments: &Shared<[u32]>, w: usize) -> u32 {
    let unit = UNIT_POS as usize;
    counts[padded(w * SORT_UNITS as usize + unit)] + segments[w * SEGMENTS + unit / SEGMENT_UNITS]
}

/// The entries of digit `d` in the tile.
#[cube]
fn tile_count(t: &TileDigits, d: usize) -> u32 {
    unpack(t.totals[d / 2], d)
}

/// `histogram[digit · tiles + tile]`: the entries of tile `tile` of `keys` (length `len`) with each digit at
/// `shift`.
#[cube(launch)]
pub fn tile_histogram_kernel(keys: &Tensor<u32>, histogram: &mut Tensor<u32>, len: u32, shift: u32, tiles: u32) {
    let tile = tile_index();
    let base = tile * SORT_TILE as usize;
    let t = count_tile(keys, base, valid_entries(base, len), shift);
    let d = UNIT_POS as usize;
    if d < DIGITS && tile < tiles as usize {
        histogram[d * tiles as usize + tile] = tile_count(&t, d);
    }
}

/// Writes tile `tile`'s entries in stable digit order to their slots: `offsets` holds the exclusive scan of
/// the histogram (each (digit, tile)'s first slot). Keys, payloads and, with `carry`, a second payload.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn tile_scatter_kernel(
    keys: &Tensor<u32>,
    values: &Tensor<u32>,
    extra: &Tensor<u32>,
    offsets: &Tensor<u32>,
    keys_out: &mut Tensor<u32>,
    values_out: &mut Tensor<u32>,
    extra_out: &mut Tensor<u32>,
    len: u32,
    shift: u32,
    tiles: u32,
    #[comptime] carry: bool,
) {
    let tile = tile_index();
    let base = tile * SORT_TILE as usize;
    let valid = valid_entries(base, len);
    let mut t = count_tile(keys, base, valid, shift);
    // `starts[d]`: digit d's first tile-local position; `slots[d]`: its first output slot minus that.
    let mut starts = Shared::<[u32]>::new_slice(DIGITS);
    let mut slots = Shared::<[u32]>::new_slice(DIGITS);
    let d = UNIT_POS as usize;
    if d < DIGITS {
        let mut start = 0u32;
        for lower in 0..d {
            start += tile_count(&t, lower);
        }
        starts[d] = start;
        let mut first = 0u32;
        if tile < tiles as usize {
            first = offsets[d * tiles as usize + tile];
        }
        slots[d] = first - start;
    }
    sync_cube();
    place_own(&mut t, &starts, valid, shift);
    #[unroll]
    for j in 0..SORT_ITEMS as usize {
        let position = j * SORT_UNITS as usize + UNIT_POS as usize;
        if position < valid {
            let i = t.counts[padded(position)] as usize;
            let key = t.keys[padded(i)];
            let slot = (slots[digit(key, shift)] + position as u32) as usize;
            keys_out[slot] = key;
            values_out[slot] = values[base + i];
            if carry {
                extra_out[slot] = extra[base + i];
            }
        }
    }
}

/// Records, at each of the unit's entries' tile-local sorted positions, the entry's tile index (in `counts`,
/// once every unit has read its prefixes from there). Every unit of the cube calls it.
#[cube]
fn place_own(t: &mut TileDigits, starts: &Shared<[u32]>, valid: usize, shift: u32) {
    let unit = UNIT_POS as usize;
    let mut next = Array::<u32>::new(DIGITS);
    #[unroll]
    for d in 0..DIGITS {
        next[d] = starts[d] + unpack(unit_prefix(&t.counts, &t.segments, d / 2), d);
    }
    sync_cube();
    #[unroll]
    for k in 0..SORT_ITEMS as usize {
        let i = unit * SORT_ITEMS as usize + k;
        if i < valid {
            let d = digit(t.keys[padded(i)], shift);
            t.counts[padded(next[d] as usize)] = i as u32;
            next[d] += 1;
        }
    }
    sync_cube();
}

/// Keys and payloads being sorted, with the buffers of the next pass.
struct Buffers {
    keys: CubeTensor,
    values: CubeTensor,
    extra: CubeTensor,
    keys_out: CubeTensor,
    values_out: CubeTensor,
    extra_out: CubeTensor,
}

impl Buffers {
    fn swap(&mut self) {
        std::mem::swap(&mut self.keys, &mut self.keys_out);
        std::mem::swap(&mut self.values, &mut self.values_out);
        std::mem::swap(&mut self.extra, &mut self.extra_out);
    }
}

/// One stable pass over the digit at `shift`; `carry` moves `extra` along.
fn sort_pass(device: &CubeDevice, b: &mut Buffers, len: usize, shift: u32, carry: bool) {
    let client = device.client();
    let tiles = len.div_ceil(SORT_TILE as usize);
    let (cubes, dim) = cube_launch(&client, tiles, SORT_UNITS);
    let histogram = buffer(device, DIGITS * tiles, DType::U32);
    let (len32, tiles32) = (len as u32, tiles as u32);
    tile_histogram_kernel::launch(&client, cubes.clone(), dim, arg(&b.keys), arg(&histogram), len32, shift, tiles32);
    let offsets = exclusive_scan(device, &histogram, DIGITS * tiles);
    tile_scatter_kernel::launch(
        &client,
        cubes,
        dim,
        arg(&b.keys),
        arg(&b.values),
        arg(&b.extra),
        arg(&offsets),
        arg(&b.keys_out),
        arg(&b.values_out),
        arg(&b.extra_out),
        len32,
        shift,
        tiles32,
        carry,
    );
    b.swap();
}

/// Passes needed for keys below `2^bits`.
pub fn passes(bits: u32) -> u32 {
    bits.div_ceil(RADIX_BITS)
}

/// Sorts `len` entries by (`major`, `minor`), both `u32`, stably, and returns (`major`, `values`) in that
/// order: [`passes`]`(minor_bits)` passes over `minor` carrying `major`, then [`passes`]`(major_bits)` over
/// `major`. Only the low `minor_bits` / `major_bits` bits of the keys are read.
pub fn sort_by_two_keys(
    device: &CubeDevice,
    major: CubeTensor,
    minor: CubeTensor,
    values: CubeTensor,
    len: usize,
    major_bits: u32,
    minor_bits: u32,
) -> (CubeTensor, CubeTensor) {
    if len <= 1 {
        return (major, values);
    }
    let mut b = Buffers {
        keys: minor,
        values,
        extra: major,
        keys_out: buffer(device, len, DType::U32),
        values_out: buffer(device, len, DType::U32),
        extra_out: buffer(device, len, DType::U32),
    };
    for pass in 0..passes(minor_bits) {
        sort_pass(device, &mut b, len, pass * RADIX_BITS, true);
    }
    // Now sort by the major key, which was carried along; the minor key is no longer needed.
    std::mem::swap(&mut b.keys, &mut b.extra);
    std::mem::swap(&mut b.keys_out, &mut b.extra_out);
    // Distinct placeholders: one buffer bound twice in a launch, once written, is not portable.
    b.extra = buffer(device, 1, DType::U32);
    b.extra_out = buffer(device, 1, DType::U32);
    for pass in 0..passes(major_bits) {
        sort_pass(device, &mut b, len, pass * RADIX_BITS, false);
    }
    (b.keys, b.values)
}
