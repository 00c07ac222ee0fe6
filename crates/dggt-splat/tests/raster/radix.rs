//! The device radix sort of tile intersections (feature `wgpu`) against a stable host sort of the same keys, on
//! keys a render rarely produces: equal depths everywhere, every entry in one list, many and empty lists,
//! lengths around the sort's cube (256 units) and tile (1024 entries) and the scan's tile (2048 values),
//! extreme depths; and the prefix sum behind it over one, two and three levels.

use dggt_splat::{SortedIntersections, prefix_sums, sort_intersections};

use crate::cube::cube_device;
use crate::scenes::Rng;

/// The host's order: by list, then depth, then input position (a stable sort), with the list ranges.
fn host_sort(lists: &[u32], depths: &[f32], list_count: usize) -> SortedIntersections {
    let mut order: Vec<u32> = (0..lists.len() as u32).collect();
    order.sort_by(|&a, &b| {
        let (a, b) = (a as usize, b as usize);
        lists[a].cmp(&lists[b]).then(depths[a].total_cmp(&depths[b]))
    });
    let sorted: Vec<u32> = order.iter().map(|&i| lists[i as usize]).collect();
    let mut ranges = vec![0u32; 2 * list_count];
    for (i, &list) in sorted.iter().enumerate() {
        let l = list as usize;
        if i == 0 || sorted[i - 1] != list {
            ranges[2 * l] = i as u32;
        }
        ranges[2 * l + 1] = i as u32 + 1;
    }
    SortedIntersections { lists: sorted, order, ranges }
}

fn check_sort(case: &str, lists: &[u32], depths: &[f32], list_count: usize) {
    let device = cube_device();
    let ours = sort_intersections(&device, lists, depths, list_count);
    let host = host_sort(lists, depths, list_count);
    assert_eq!(ours.lists, host.lists, "{case}: sorted lists");
    assert_eq!(ours.order, host.order, "{case}: order (stability)");
    assert_eq!(ours.ranges, host.ranges, "{case}: list ranges");
    eprintln!("{case}: {} entries in {list_count} lists sorted as the host sorts them", lists.len());
}

fn random_lists(rng: &mut Rng, len: usize, list_count: usize) -> Vec<u32> {
    (0..len).map(|_| rng.below(list_count) as u32).collect()
}

/// Depths from a few distinct values, so that many entries tie.
fn tied_depths(rng: &mut Rng, len: usize) -> Vec<f32> {
    (0..len).map(|_| [0.5f32, 1.0, 2.0, 7.25][rng.below(4)]).collect()
}

#[test]
fn radix_sort_keeps_input_order_for_equal_depths() {
    let mut rng = Rng::new(1);
    let lists = random_lists(&mut rng, 5000, 37);
    check_sort("all depths equal", &lists, &vec![3.5; 5000], 37);
}

#[test]
fn radix_sort_keeps_input_order_for_equal_keys() {
    // Every key equal: each pass's scatter must keep the identity order, within and across tiles.
    check_sort("all keys equal", &vec![3; 5000], &vec![2.0; 5000], 4);
}

#[test]
fn radix_sort_handles_one_list_holding_every_entry() {
    let mut rng = Rng::new(2);
    let depths = tied_depths(&mut rng, 4097);
    check_sort("one list, tied depths", &vec![5; 4097], &depths, 6);
    let depths = rng.ranges(4097, 0.01, 100.0);
    check_sort("one list, distinct depths", &vec![0; 4097], &depths, 1);
}

#[test]
fn radix_sort_handles_many_lists_and_empty_ones() {
    let mut rng = Rng::new(3);
    // 100 000 lists (17 bits: five passes over the list bits), most of them empty.
    let lists = random_lists(&mut rng, 30_001, 100_000);
    let depths = rng.ranges(30_001, 0.01, 50.0);
    check_sort("many lists", &lists, &depths, 100_000);
    // Views without intersections: lists only in the first and last of five views of 12 tiles.
    let lists: Vec<u32> =
        (0..3000).map(|i| if i % 2 == 0 { rng.below(12) } else { 48 + rng.below(12) } as u32).collect();
    let depths = tied_depths(&mut rng, 3000);
    check_sort("empty views", &lists, &depths, 60);
}

#[test]
fn radix_sort_handles_lengths_around_the_tile_sizes() {
    let mut rng = Rng::new(4);
    for len in [0, 1, 2, 255, 256, 257, 1000, 1023, 1024, 1025, 2047, 2048, 2049, 4097, 65_537] {
        let lists = random_lists(&mut rng, len, 9);
        let depths = tied_depths(&mut rng, len);
        check_sort(&format!("length {len}"), &lists, &depths, 9);
    }
}

#[test]
fn radix_sort_orders_extreme_depths() {
    let mut rng = Rng::new(5);
    let extremes = [f32::MIN_POSITIVE, 1e-40, 1e-30, 0.01, 1.0, 1.0000001, 1e10, 1e30, f32::MAX];
    let depths: Vec<f32> = (0..3000).map(|_| extremes[rng.below(extremes.len())]).collect();
    let lists = random_lists(&mut rng, 3000, 4);
    check_sort("extreme depths", &lists, &depths, 4);
}

#[test]
fn radix_sort_of_a_large_batch_matches_the_host() {
    // 300 000 entries: 293 tiles of 1024, a histogram of 4688 counts scanned over two levels.
    let mut rng = Rng::new(6);
    let lists = random_lists(&mut rng, 300_000, 4056);
    let depths = rng.ranges(300_000, 0.01, 80.0);
    check_sort("large", &lists, &depths, 4056);
}

#[test]
fn prefix_sums_over_three_levels_match_the_host() {
    let device = cube_device();
    let mut rng = Rng::new(7);
    // Tiles of 2048: up to 2048 values take one level, up to 2048² two, 2048² + 1 three (2049 tile sums,
    // then 2).
    for len in [0usize, 1, 255, 256, 257, 2047, 2048, 2049, 70_000, 1_100_000, 4_194_304, 4_194_305] {
        let values: Vec<u32> = (0..len).map(|_| rng.below(40) as u32).collect();
        let ours = prefix_sums(&device, &values);
        let mut expected = Vec::with_capacity(len + 1);
        let mut running = 0u32;
        for v in &values {
            expected.push(running);
            running += v;
        }
        expected.push(running);
        assert_eq!(ours, expected, "prefix sums of {len} values");
    }
}

#[test]
fn prefix_sums_wrap_past_u32() {
    let device = cube_device();
    let mut rng = Rng::new(8);
    // Sums pass 2^32 many times, within tiles and across them.
    let values: Vec<u32> = (0..5000).map(|_| (1 << 31) + rng.below(1000) as u32).collect();
    let ours = prefix_sums(&device, &values);
    let mut expected = vec![0u32];
    for v in &values {
        expected.push(expected.last().unwrap().wrapping_add(*v));
    }
    assert_eq!(ours, expected, "wrapping prefix sums");
}
