//! The exclusive prefix sum that turns per-list intersection counts into list offsets, in one cube.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

/// Threads per cube of the one-cube prefix sum.
pub const SCAN_THREADS: u32 = 256;
/// [`SCAN_THREADS`] as the length of the shared segment sums.
const SCAN_LEN: usize = SCAN_THREADS as usize;

/// Exclusive prefix sum of `counts` (length `len`) into `offsets` (length `len + 1`), in one cube of
/// [`SCAN_THREADS`] units: each unit sums a contiguous segment of `segment = ceil(len / SCAN_THREADS)` entries,
/// one unit scans the segment sums, then each unit writes its segment. `total[0]` receives the sum.
#[cube(launch)]
pub fn scan_kernel(counts: &Tensor<u32>, offsets: &mut Tensor<u32>, total: &mut Tensor<u32>, len: u32, segment: u32) {
    let mut partial = Shared::<[u32]>::new_slice(SCAN_LEN);
    let unit = UNIT_POS_X;
    let start = (unit * segment).min(len);
    let end = (start + segment).min(len);
    let mut sum = 0u32;
    for i in start..end {
        sum += counts[i as usize];
    }
    partial[unit as usize] = sum;
    sync_cube();
    if unit == 0 {
        let mut running = 0u32;
        for t in 0..SCAN_THREADS {
            let value = partial[t as usize];
            partial[t as usize] = running;
            running += value;
        }
        offsets[len as usize] = running;
        total[0] = running;
    }
    sync_cube();
    let mut running = partial[unit as usize];
    for i in start..end {
        offsets[i as usize] = running;
        running += counts[i as usize];
    }
}
