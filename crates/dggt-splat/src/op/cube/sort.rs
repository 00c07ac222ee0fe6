//! Ordering the intersections: a bitonic sort of every list of every view at once, by list, depth and
//! Gaussian index, on a power-of-two length padded past the last real entry.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

/// Marks the entries past the last intersection (the sort runs on a power-of-two length) with a list index
/// above every real one, so they sort to the end.
#[cube(launch)]
pub fn pad_kernel(
    entry_lists: &mut Tensor<u32>,
    entry_depths: &mut Tensor<f32>,
    entry_ids: &mut Tensor<u32>,
    from: u32,
    len: u32,
) {
    let i = ABSOLUTE_POS as u32 + from;
    if i >= len {
        terminate!();
    }
    entry_lists[i as usize] = u32::MAX;
    entry_depths[i as usize] = 0.0;
    entry_ids[i as usize] = i;
}

/// Whether entry `a` goes before entry `b`: by list, then depth (front to back), then Gaussian index (the
/// host's order for equal depths). A strict total order, so the sorted result does not depend on the arrival
/// order the atomics of [`fill_kernel`] gave.
#[cube]
pub fn entry_before(list_a: u32, depth_a: f32, id_a: u32, list_b: u32, depth_b: f32, id_b: u32) -> bool {
    list_a < list_b || (list_a == list_b && (depth_a < depth_b || (depth_a == depth_b && id_a < id_b)))
}

/// One compare-and-exchange stage `(block, stride)` of a bitonic sort of all entries at once (every list of
/// every view), one unit per pair: `log2(len) · (log2(len) + 1) / 2` launches sort `len` (a power of two)
/// entries. Each unit does constant work, so no list length makes a unit run long.
#[cube(launch)]
pub fn bitonic_step_kernel(
    entry_lists: &mut Tensor<u32>,
    entry_depths: &mut Tensor<f32>,
    entry_ids: &mut Tensor<u32>,
    block: u32,
    stride: u32,
    len: u32,
) {
    let pair = ABSOLUTE_POS as u32;
    if pair >= len / 2 {
        terminate!();
    }
    let low = (pair / stride) * 2 * stride + pair % stride;
    let high = low + stride;
    let ascending = (low & block) == 0;
    let (a, b) = (low as usize, high as usize);
    let (list_a, depth_a, id_a) = (entry_lists[a], entry_depths[a], entry_ids[a]);
    let (list_b, depth_b, id_b) = (entry_lists[b], entry_depths[b], entry_ids[b]);
    if entry_before(list_b, depth_b, id_b, list_a, depth_a, id_a) == ascending {
        entry_lists[a] = list_b;
        entry_depths[a] = depth_b;
        entry_ids[a] = id_b;
        entry_lists[b] = list_a;
        entry_depths[b] = depth_a;
        entry_ids[b] = id_a;
    }
}
