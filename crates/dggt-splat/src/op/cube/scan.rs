//! Exclusive prefix sums of `u32` counts of any length, on the device: each unit sums one block of
//! [`SCAN_BLOCK`] values, the block sums are scanned the same way (recursively, until one block holds them
//! all), and each unit then writes its block's prefixes from its block's offset. `len` values take
//! `⌈log_256 len⌉` levels of two launches each, the values read twice and written once.
//!
//! Units work serially on their blocks and share nothing: no shared memory and no barriers, which keeps the
//! kernels compilable on every device (lavapipe's SPIR-V compiler rejects the shared memory CubeCL emits
//! where Vulkan's explicit workgroup layout is missing).
//!
//! Sums are `u32` and wrap past `2^32`; a difference of two prefixes is still exact while the values between
//! them sum to less than `2^32`.

use burn::backend::DType;
use burn_cubecl::CubeDevice;
use burn_cubecl::cubecl;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::tensor::CubeTensor;

use super::{arg, buffer, element_launch, zeroed};

/// Values one unit scans.
pub const SCAN_BLOCK: u32 = 256;

/// `sums[b]`: the sum of block `b` of `values` (length `len`).
#[cube(launch)]
pub fn block_sums_kernel(values: &Tensor<u32>, sums: &mut Tensor<u32>, len: u32, blocks: u32) {
    let b = ABSOLUTE_POS;
    if b >= blocks as usize {
        terminate!();
    }
    let start = b * SCAN_BLOCK as usize;
    let end = (start + SCAN_BLOCK as usize).min(len as usize);
    let mut sum = 0u32;
    for i in start..end {
        sum += values[i];
    }
    sums[b] = sum;
}

/// Writes the exclusive prefixes of block `b` of `values`, starting from `offsets[b]`; the last block also
/// writes the total to `prefix[len]`.
#[cube(launch)]
pub fn block_prefixes_kernel(
    values: &Tensor<u32>,
    offsets: &Tensor<u32>,
    prefix: &mut Tensor<u32>,
    len: u32,
    blocks: u32,
) {
    let b = ABSOLUTE_POS;
    if b >= blocks as usize {
        terminate!();
    }
    let start = b * SCAN_BLOCK as usize;
    let end = (start + SCAN_BLOCK as usize).min(len as usize);
    let mut running = offsets[b];
    for i in start..end {
        let value = values[i];
        prefix[i] = running;
        running += value;
    }
    if b + 1 == blocks as usize {
        prefix[len as usize] = running;
    }
}

/// The exclusive prefix sum of the first `len` values of `values` (`u32`), `len + 1` long: entry `len` is
/// the total.
pub fn exclusive_scan(device: &CubeDevice, values: &CubeTensor, len: usize) -> CubeTensor {
    let client = device.client();
    let prefix = buffer(device, len + 1, DType::U32);
    let blocks = len.div_ceil(SCAN_BLOCK as usize).max(1);
    let offsets = if blocks == 1 {
        zeroed(device, 1, DType::U32)
    } else {
        let sums = buffer(device, blocks, DType::U32);
        let (cubes, dim) = element_launch(&client, blocks);
        block_sums_kernel::launch(&client, cubes, dim, arg(values), arg(&sums), len as u32, blocks as u32);
        exclusive_scan(device, &sums, blocks)
    };
    let (cubes, dim) = element_launch(&client, blocks);
    block_prefixes_kernel::launch(
        &client,
        cubes,
        dim,
        arg(values),
        arg(&offsets),
        arg(&prefix),
        len as u32,
        blocks as u32,
    );
    prefix
}
