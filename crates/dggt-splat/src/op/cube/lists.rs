//! The sorted tile lists, built batch by batch so that no intersection buffer exceeds the device's limit.
//!
//! After `count_kernel` has counted every (view, Gaussian) pair's tiles, the exclusive scan of those counts
//! gives each pair its offset, and `view_starts_kernel` picks the offsets at view boundaries: `V + 1`
//! integers, the one read-back of the forward pass, from which [`plan_batches`] groups consecutive views
//! into batches of at most [`max_entries`] intersections. Each batch is then filled (in pair order), radix
//! sorted by (list, depth) and cut into per-list ranges ([`sorted_batch`]). The per-entry buffers of one batch
//! are `4` bytes an entry, so the cap on entries is the cap on bytes over 4.

use std::ops::Range;

use burn::backend::DType;
use burn_cubecl::CubeDevice;
use burn_cubecl::cubecl;
use burn_cubecl::ops::into_data_sync;
use burn_cubecl::tensor::CubeTensor;

use super::timing::StageClock;
use super::{Layout, arg, bin, buffer, element_launch, radix, zeroed};
use crate::settings::RasterSettings;

/// Bytes per intersection in each per-entry buffer (keys and payloads are `u32`).
const ENTRY_BYTES: u64 = 4;

/// The sorted tile lists of the views `first_view..first_view + views`: list `l` (of view
/// `first_view + l / tiles`) holds the Gaussians `ids[ranges[2 l]..ranges[2 l + 1]]`, front to back.
#[derive(Clone)]
pub struct ListBatch {
    pub first_view: usize,
    pub views: usize,
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

/// Consecutive views grouped greedily into batches of at most `max_entries` intersections.
///
/// # Panics
///
/// When one view alone has more intersections than `max_entries`.
pub fn plan_batches(per_view: &[u64], max_entries: u64) -> Vec<Range<usize>> {
    let mut batches = Vec::new();
    let (mut start, mut total) = (0, 0u64);
    for (v, &count) in per_view.iter().enumerate() {
        assert!(
            count <= max_entries,
            "splat: view {v} has {count} tile intersections, {} bytes a buffer, beyond the cap of {} bytes a \
             buffer ({max_entries} intersections); lower the resolution or the number of Gaussians",
            count * ENTRY_BYTES,
            max_entries * ENTRY_BYTES,
        );
        if v > start && total + count > max_entries {
            batches.push(start..v);
            (start, total) = (v, 0);
        }
        total += count;
    }
    if start < per_view.len() {
        batches.push(start..per_view.len());
    }
    batches
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

/// Fills, sorts and ranges the lists of the views `views` holding `entries` intersections, which start at
/// `base` in pair order.
pub fn sorted_batch(
    device: &CubeDevice,
    layout: &Layout,
    f: &FootprintBuffers,
    views: Range<usize>,
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
    let batch = |ids| ListBatch { first_view: views.start, views: views.len(), ranges: ranges.clone(), ids };
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
