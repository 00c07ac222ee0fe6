//! The sorted tile lists, built batch by batch so that no intersection buffer exceeds the device's limit.
//!
//! After `count_kernel` has counted every (view, Gaussian) pair's tiles, the exclusive scan of those counts
//! gives each pair its offset, and `view_starts_kernel` picks the offsets at view boundaries: `V + 1`
//! integers, the one read-back of the forward pass, from which [`plan_batches`] groups consecutive views
//! into batches of at most [`max_entries`] intersections. Each batch is then filled (in pair order), radix
//! sorted by (list, depth) and cut into per-list ranges ([`sorted_batch`]). The per-entry buffers of one batch
//! are `4` bytes an entry, so the cap on entries is the cap on bytes over 4.
//!
//! A view with more intersections than that is split into bands of its tile rows ([`view_bands`]: its
//! intersections per tile row, read back, grouped greedily under the cap); each band is counted, scanned,
//! filled and sorted on its own ([`sorted_band`]), and compositing runs on the band's rows alone. A tile's
//! list is whole in one band, so the images do not depend on the bands. Only a single tile row beyond the cap
//! is refused.

use std::ops::Range;

use burn::backend::DType;
use burn_cubecl::CubeDevice;
use burn_cubecl::cubecl;
use burn_cubecl::ops::into_data_sync;
use burn_cubecl::tensor::CubeTensor;

use super::timing::StageClock;
use super::{Layout, arg, bin, buffer, element_launch, radix, scan, zeroed};
use crate::settings::RasterSettings;

/// Bytes per intersection in each per-entry buffer (keys and payloads are `u32`).
const ENTRY_BYTES: u64 = 4;

/// The sorted tile lists of the views `first_view..first_view + views`: list `l` (of view
/// `first_view + l / tiles`) holds the Gaussians `ids[ranges[2 l]..ranges[2 l + 1]]`, front to back.
#[derive(Clone)]
pub struct ListBatch {
    pub first_view: usize,
    pub views: usize,
    /// The tile rows whose lists the batch holds (every row, but for a band of one view's rows).
    pub rows: Range<u32>,
    pub ranges: CubeTensor,
    pub ids: CubeTensor,
}

/// The largest single buffer the rasteriser allocates: the device's limit on one storage buffer
/// (`max_page_size`: wgpu's storage binding and buffer size limits), lowered by
/// [`RasterSettings::max_buffer_bytes`] when set.
pub fn buffer_cap(client: &cubecl::client::Client, settings: &RasterSettings) -> u64 {
    let device = client.properties().memory.max_page_size;
    settings.max_buffer_bytes.map_or(device, |cap| cap.min(device))
}

/// Intersections one batch may hold under `cap` bytes a buffer (and within `u32` indexing).
pub fn max_entries(cap: u64) -> u64 {
    (cap / ENTRY_BYTES).min(u64::from(u32::MAX))
}

/// Consecutive views grouped greedily into batches of at most `max_entries` intersections; a view with more
/// is a batch of its own (to be split into bands of tile rows by [`view_bands`]).
pub fn plan_batches(per_view: &[u64], max_entries: u64) -> Vec<Range<usize>> {
    group_greedily(per_view, max_entries)
}

/// Consecutive tile rows grouped greedily into bands of at most `max_entries` intersections, from the view's
/// intersections per row.
///
/// # Panics
///
/// When one tile row alone has more intersections than `max_entries`.
pub fn plan_bands(view: usize, per_row: &[u64], max_entries: u64) -> Vec<Range<u32>> {
    if let Some((row, &count)) = per_row.iter().enumerate().find(|&(_, &count)| count > max_entries) {
        panic!(
            "splat: tile row {row} of view {view} has {count} tile intersections, {} bytes a buffer, beyond the \
             cap of {} bytes a buffer ({max_entries} intersections); lower the resolution or the number of \
             Gaussians",
            count * ENTRY_BYTES,
            max_entries * ENTRY_BYTES,
        );
    }
    group_greedily(per_row, max_entries).into_iter().map(|rows| rows.start as u32..rows.end as u32).collect()
}

/// Consecutive items grouped greedily into runs whose counts sum to at most `max`; an item above `max` is a run
/// of its own.
fn group_greedily(counts: &[u64], max: u64) -> Vec<Range<usize>> {
    let mut runs = Vec::new();
    let (mut start, mut total) = (0, 0u64);
    for (i, &count) in counts.iter().enumerate() {
        if i > start && (total + count > max || count > max) {
            runs.push(start..i);
            (start, total) = (i, 0);
        }
        total += count;
    }
    if start < counts.len() {
        runs.push(start..counts.len());
    }
    runs
}

/// Where each view's intersections start in pair order (`V + 1` values, read back): `pair_offsets` at every
/// view boundary. The differences are the per-view totals (exact, whatever the `u32` sums wrapped).
pub fn view_starts(device: &CubeDevice, layout: &Layout, pair_offsets: &CubeTensor) -> Vec<u32> {
    let client = device.client();
    let starts = buffer(device, layout.views + 1, DType::U32);
    let (cubes, dim) = element_launch(&client, layout.views + 1);
    bin::view_starts_kernel::launch(&client, cubes, dim, arg(pair_offsets), arg(&starts), layout.grid());
    into_data_sync(starts).iter::<u32>().take(layout.views + 1).collect()
}

/// Intersections per view from [`view_starts`].
pub fn per_view_counts(starts: &[u32]) -> Vec<u64> {
    starts.windows(2).map(|w| u64::from(w[1].wrapping_sub(w[0]))).collect()
}

/// The footprints the fill reads, per (view, Gaussian) pair.
pub struct FootprintBuffers<'a> {
    pub means2d: &'a CubeTensor,
    pub radii: &'a CubeTensor,
    pub reasons: &'a CubeTensor,
    pub depths: &'a CubeTensor,
    pub pair_offsets: &'a CubeTensor,
}

/// Bits needed for the values `0..n`.
pub fn bits_for(n: usize) -> u32 {
    usize::BITS - n.saturating_sub(1).leading_zeros()
}

/// The bands of tile rows [`plan_bands`] splits `view` into, each with its intersections, from the view's
/// intersections per row (a count pass and one read-back of `tiles_y` integers).
pub fn view_bands(
    device: &CubeDevice,
    layout: &Layout,
    f: &FootprintBuffers,
    view: usize,
    cap: u64,
) -> Vec<(Range<u32>, usize)> {
    let client = device.client();
    let per_row = zeroed(device, layout.tiles_y as usize, DType::U32);
    let (cubes, dim) = element_launch(&client, layout.count);
    let (means2d, radii, reasons) = (arg(f.means2d), arg(f.radii), arg(f.reasons));
    bin::row_counts_kernel::launch(
        &client,
        cubes,
        dim,
        means2d,
        radii,
        reasons,
        arg(&per_row),
        layout.grid(),
        view as u32,
    );
    let per_row: Vec<u64> = into_data_sync(per_row).iter::<u32>().map(u64::from).collect();
    let entries = |rows: &Range<u32>| per_row[rows.start as usize..rows.end as usize].iter().sum::<u64>() as usize;
    plan_bands(view, &per_row, cap).into_iter().map(|rows| (rows.clone(), entries(&rows))).collect()
}

/// Fills, sorts and ranges the lists of `view`'s tile rows `rows`, which hold `entries` intersections.
pub fn sorted_band(
    device: &CubeDevice,
    layout: &Layout,
    f: &FootprintBuffers,
    view: usize,
    rows: Range<u32>,
    entries: usize,
    clock: &mut StageClock,
) -> ListBatch {
    let client = device.client();
    let pair_counts = buffer(device, layout.pairs(), DType::U32);
    let (cubes, dim) = element_launch(&client, layout.pairs());
    bin::band_count_kernel::launch(
        &client,
        cubes,
        dim,
        arg(f.means2d),
        arg(f.radii),
        arg(f.reasons),
        arg(&pair_counts),
        layout.grid(),
        view as u32,
        rows.start,
        rows.end,
    );
    let band_offsets = scan::exclusive_scan(device, &pair_counts, layout.pairs());
    let band = FootprintBuffers { pair_offsets: &band_offsets, ..*f };
    // Every pair before the view counts nothing here, so the band's entries start at 0.
    sorted_batch(device, layout, &band, view..view + 1, rows, 0, entries, clock)
}

/// Fills, sorts and ranges the lists of the views `views` in the tile rows `rows`, holding `entries`
/// intersections, which start at `base` in pair order.
#[allow(clippy::too_many_arguments)]
pub fn sorted_batch(
    device: &CubeDevice,
    layout: &Layout,
    f: &FootprintBuffers,
    views: Range<usize>,
    rows: Range<u32>,
    base: u32,
    entries: usize,
    clock: &mut StageClock,
) -> ListBatch {
    let client = device.client();
    let lists = views.len() * layout.tiles();
    let ranges = zeroed(device, 2 * lists, DType::U32);
    let entry_lists = buffer(device, entries, DType::U32);
    let entry_depths = buffer(device, entries, DType::U32);
    let entry_ids = buffer(device, entries, DType::U32);
    let batch = |ids| ListBatch {
        first_view: views.start,
        views: views.len(),
        rows: rows.clone(),
        ranges: ranges.clone(),
        ids,
    };
    if entries == 0 {
        return batch(entry_ids);
    }
    let (cubes, dim) = element_launch(&client, views.len() * layout.count);
    bin::fill_kernel::launch(
        &client,
        cubes,
        dim,
        arg(f.means2d),
        arg(f.radii),
        arg(f.reasons),
        arg(f.depths),
        arg(f.pair_offsets),
        arg(&entry_lists),
        arg(&entry_depths),
        arg(&entry_ids),
        layout.grid(),
        views.start as u32,
        views.len() as u32,
        base,
        rows.start,
        rows.end,
    );
    clock.mark(|| format!("views {}.. fill of {entries}", views.start));
    let (sorted_lists, ids) =
        radix::sort_by_two_keys(device, entry_lists, entry_depths, entry_ids, entries, bits_for(lists), 32);
    clock.mark(|| format!("views {}.. radix sort", views.start));
    let (cubes, dim) = element_launch(&client, entries);
    bin::ranges_kernel::launch(&client, cubes, dim, arg(&sorted_lists), arg(&ranges), entries as u32);
    clock.mark(|| format!("views {}.. ranges", views.start));
    batch(ids)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn greedy_runs_stay_under_the_cap_and_an_item_above_it_runs_alone() {
        assert_eq!(plan_batches(&[3, 2, 2, 9, 1, 1], 5), vec![0..2, 2..3, 3..4, 4..6]);
        assert_eq!(plan_bands(0, &[2, 2, 1, 4], 4), vec![0..2, 2..3, 3..4]);
        assert_eq!(plan_bands(0, &[1, 1, 1], 10), vec![0..3]);
        assert!(plan_batches(&[], 5).is_empty());
    }

    #[test]
    #[should_panic(expected = "tile row 1 of view 3 has 7 tile intersections, 28 bytes a buffer")]
    fn a_tile_row_above_the_cap_is_refused_naming_it() {
        plan_bands(3, &[1, 7], 4);
    }
}
