//! A stable least-significant-digit radix sort of `u32` keys with `u32` payloads, [`RADIX_BITS`] bits a pass.
//!
//! A pass over digit `shift..shift + RADIX_BITS`, for `len` entries split into runs of [`SORT_RUN`], one run
//! per unit:
//!
//! 1. [`digit_pass_kernel`] without `scatter`: each unit counts its run's entries per digit, written
//!    digit-major (`histogram[digit · runs + run]`), so that
//! 2. one exclusive scan of the whole histogram gives every (digit, run) its first output slot;
//! 3. [`digit_pass_kernel`] with `scatter`: each unit writes its run's entries in order from those slots.
//!    Entries with equal digits keep their order: the sort is stable.
//!
//! Units share nothing (no shared memory, no barriers, no atomics), so the result does not depend on
//! scheduling and the kernels compile on every device, lavapipe included. The histogram holds
//! `16 / SORT_RUN` counts per entry, which its scan reads and writes twice.

use burn::backend::DType;
use burn_cubecl::CubeDevice;
use burn_cubecl::cubecl;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::tensor::CubeTensor;

use super::scan::exclusive_scan;
use super::{arg, buffer, element_launch};

/// Bits of the key sorted per pass.
pub const RADIX_BITS: u32 = 4;
/// Distinct digits of a pass.
const DIGITS: usize = 1 << RADIX_BITS;
/// Consecutive entries each unit counts and scatters.
pub const SORT_RUN: u32 = 256;

/// The digit of `key` at `shift`.
#[cube]
fn digit(key: u32, shift: u32) -> usize {
    ((key >> shift) & (DIGITS as u32 - 1)) as usize
}

/// One pass over the digit at `shift` for run `ABSOLUTE_POS` of [`SORT_RUN`] entries. Without `scatter`,
/// writes the run's per-digit counts to `histogram[digit · runs + run]`; with `scatter`, `histogram` holds
/// the exclusive scan of those counts (each (digit, run)'s first slot) and the run's entries are written in
/// order to their slots: keys, payloads and, with `carry`, a second payload.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn digit_pass_kernel(
    keys: &Tensor<u32>,
    values: &Tensor<u32>,
    extra: &Tensor<u32>,
    histogram: &mut Tensor<u32>,
    keys_out: &mut Tensor<u32>,
    values_out: &mut Tensor<u32>,
    extra_out: &mut Tensor<u32>,
    len: u32,
    shift: u32,
    runs: u32,
    #[comptime] scatter: bool,
    #[comptime] carry: bool,
) {
    let run = ABSOLUTE_POS;
    if run >= runs as usize {
        terminate!();
    }
    let start = run * SORT_RUN as usize;
    let end = (start + SORT_RUN as usize).min(len as usize);
    let runs = runs as usize;
    if !scatter {
        let mut counts = Array::<u32>::new(DIGITS);
        #[unroll]
        for d in 0..DIGITS {
            counts[d] = 0;
        }
        for i in start..end {
            counts[digit(keys[i], shift)] += 1;
        }
        #[unroll]
        for d in 0..DIGITS {
            histogram[d * runs + run] = counts[d];
        }
    } else {
        let mut next = Array::<u32>::new(DIGITS);
        #[unroll]
        for d in 0..DIGITS {
            next[d] = histogram[d * runs + run];
        }
        for i in start..end {
            let key = keys[i];
            let d = digit(key, shift);
            let target = next[d] as usize;
            next[d] += 1;
            keys_out[target] = key;
            values_out[target] = values[i];
            if carry {
                extra_out[target] = extra[i];
            }
        }
    }
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
    let runs = len.div_ceil(SORT_RUN as usize);
    let (cubes, dim) = element_launch(&client, runs);
    let histogram = buffer(device, DIGITS * runs, DType::U32);
    let launch = |histogram: &CubeTensor, scatter: bool| {
        digit_pass_kernel::launch(
            &client,
            cubes.clone(),
            dim,
            arg(&b.keys),
            arg(&b.values),
            arg(&b.extra),
            arg(histogram),
            arg(&b.keys_out),
            arg(&b.values_out),
            arg(&b.extra_out),
            len as u32,
            shift,
            runs as u32,
            scatter,
            carry,
        )
    };
    launch(&histogram, false);
    launch(&exclusive_scan(device, &histogram, DIGITS * runs), true);
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
