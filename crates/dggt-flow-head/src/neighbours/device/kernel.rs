//! The brute-force k-nearest kernel: one unit per query, [`UNITS`] queries a cube; the target points pass
//! through shared memory a tile of [`UNITS`] at a time (each unit loads one), and every unit keeps its `k` best
//! rows sorted in local arrays, inserting a closer point by shifting the farther ones down.
//!
//! The tile count is read through `workgroup_uniform_load`, so that the barriers around each tile sit in uniform
//! control flow (WGSL's rule); units past the last query search on (for the barriers) and write nothing.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

/// Queries (units) per cube, and target points per shared tile.
pub const UNITS: usize = 64;

/// Writes `rows [N, k]` (`i32`): the `k` rows of `targets [M, 3]` nearest each row of `queries [N, 3]`, nearest
/// first, ties in target order.
#[cube(launch)]
pub fn k_nearest_kernel(
    queries: &Tensor<f32>,
    targets: &Tensor<f32>,
    rows: &mut Tensor<i32>,
    count: u32,
    targets_len: u32,
    #[comptime] k: usize,
) {
    let cube = (CUBE_POS_Y * CUBE_COUNT_X + CUBE_POS_X) as usize;
    let query = cube * UNITS + UNIT_POS as usize;
    let valid = query < count as usize;
    let mut q = query;
    if !valid {
        q = count as usize - 1;
    }
    let (qx, qy, qz) = (queries[3 * q], queries[3 * q + 1], queries[3 * q + 2]);

    let mut best_distance = Array::<f32>::new(k);
    let mut best_row = Array::<u32>::new(k);
    for slot in 0..k {
        best_distance[slot] = f32::MAX;
        best_row[slot] = slot as u32;
    }

    let mut bound = Shared::<[u32]>::new_slice(1usize);
    if UNIT_POS == 0 {
        bound[0] = targets_len;
    }
    let len = workgroup_uniform_load(&bound[0]) as usize;
    let mut tile = Shared::<[f32]>::new_slice(comptime!(3 * UNITS));
    let tiles = len.div_ceil(UNITS);
    for t in 0..tiles {
        let start = t * UNITS;
        let load = start + UNIT_POS as usize;
        if load < len {
            tile[3 * UNIT_POS as usize] = targets[3 * load];
            tile[3 * UNIT_POS as usize + 1] = targets[3 * load + 1];
            tile[3 * UNIT_POS as usize + 2] = targets[3 * load + 2];
        }
        sync_cube();
        let mut in_tile = len - start;
        if in_tile > UNITS {
            in_tile = UNITS.runtime();
        }
        for i in 0..in_tile {
            let (dx, dy, dz) = (tile[3 * i] - qx, tile[3 * i + 1] - qy, tile[3 * i + 2] - qz);
            let distance = dx * dx + dy * dy + dz * dz;
            if distance < best_distance[k - 1] {
                // The sorted list's tail farther than `distance` moves down one slot; `slot` ends where it goes.
                let mut slot = (k - 1).runtime();
                for step in 1..k {
                    let s = k - step;
                    if best_distance[s - 1] > distance {
                        best_distance[s] = best_distance[s - 1];
                        best_row[s] = best_row[s - 1];
                        slot = s - 1;
                    }
                }
                best_distance[slot] = distance;
                best_row[slot] = (start + i) as u32;
            }
        }
        sync_cube();
    }
    if valid {
        for slot in 0..k {
            rows[query * k + slot] = best_row[slot] as i32;
        }
    }
}
