//! [`SplatKernels`] for burn's CubeCL backend: the host pipeline's stages as CubeCL kernels, so that one kernel
//! set runs on every CubeCL runtime (wgpu/Vulkan/Metal, CUDA, ROCm).
//!
//! The kernels, one module per stage, all in `f32`: [`args`] (the arguments launches share), [`math`] (shared device
//! math and the atomic float add), [`project`], tile binning ([`bin`]: count, fill, list ranges; [`scan`]: prefix sums;
//! [`radix`]: the sort; [`lists`]: batching them under the buffer cap), [`composite`], and the backward kernels
//! [`composite_backward`] and [`project_backward`]; [`timing`] writes each stage's time on request. Every kernel reads
//! and writes flat, contiguous buffers with the layouts of the host pipeline (`Projection`, `TileBins`, `Images`):
//! index `k = v * N + n` for per-(view, Gaussian) values, pixel `p = (v * H + y) * W + x` for per-pixel values. Sizes
//! arrive as runtime `u32` scalars, grouped in one [`args::Grid`] argument built by `Layout::grid`, and the buffers
//! both compositing passes read in one [`args::BlendInputs`]; only the number of colour channels is a compile-time
//! constant (one compiled kernel per `K`), so that per-pixel colour accumulators live in registers. Their constants are
//! [`crate::constants`].
//!
//! Forward, for `V` views:
//!
//! 1. `project_kernel`: one unit per (view, Gaussian) projects and culls exactly as the host does (same rules
//!    and order, same culling codes), in `f32` where the host uses `f64`.
//! 2. `count_kernel`: the number of tiles each pair touches, and the statistics rows (atomics).
//! 3. `exclusive_scan` of the pair counts: each pair's offset into the intersections, in pair order.
//!    `view_starts_kernel` picks the offsets at view boundaries, **read back to the host** (`V + 1` integers,
//!    the only device-to-host transfer of the forward pass), which group the views into batches whose
//!    per-entry buffers fit the buffer cap (`lists`); a view beyond the cap is split into bands of its tile rows
//!    (its intersections per row read back), each band a batch of its own.
//! 4. Per batch: `fill_kernel` writes each pair's entries at its own offset (deterministic, no atomics): key
//!    (list, depth bits), payload Gaussian index; `radix` sorts them stably by depth, then by list (so equal
//!    depths keep index order, the host's); `ranges_kernel` finds each list's range; `composite_kernel`
//!    blends front to back with gsplat's classic rules, one cube per tile and one unit per pixel, the tile's
//!    footprints staged through shared memory so that each is read from global memory once per tile.
//!
//! Backward: per batch, `composite_backward_kernel` walks each tile's list back to front (one cube per tile,
//! footprints staged as in the forward) and adds footprint gradients with atomics, summed across each plane
//! first where the device has plane operations (one add per plane instead of one per pixel); the adds are
//! native `f32` atomics where the device has them, a compare-and-swap loop on `u32` bits otherwise;
//! `project_backward_kernel` pulls them through the projection, one unit per Gaussian summing
//! its views in order; the background gradient `Σ_pixels dL/dcolour · T_final` is a reduction on tensors.
//!
//! Launches and passes over memory, for `V = 12` views of 518x350 (16-pixel tiles: `726 · 12 = 8712` lists,
//! 14 bits), `N = 2.2M` Gaussians (`26.4M` pairs) and `I` intersections, `L = ⌈log2 I⌉`:
//!
//! | | before (bitonic) | now (radix) |
//! |---|---|---|
//! | binning | zero, count, one-cube scan, zero, fill (atomic cursors), pad: 6 launches | count, pair scan (5 launches: 3 levels of 2048), view starts, per batch zero and fill |
//! | sort | `L (L + 1) / 2` launches (378 at `I ≈ 10^8`, 435 at `2^29`), each reading and writing all `2^L` padded entries | 12 passes (8 over the depth bits, 4 over the 14 list bits) of 2 launches plus a histogram scan (`I / 64` counts: 3 launches at `I = 10^8`): 60 launches |
//! | sort traffic | `24 · 2^L` B per launch: ≈ 1.6 TB at `I ≈ 10^8` (`2^27`), 5.6 TB at `2^29` | 28 B/entry per depth pass, 20 B/entry per list pass, ≈ 4 B/entry of histograms and their scans: ≈ 0.31 kB per intersection, 31 GB at `10^8`, in coalesced tiles |
//! | forward launches | ≈ 9 + `L (L + 1) / 2`: 387 at `10^8`, 444 at `2^29` | ≈ 8 + 64 per batch: ≈ 72 with one batch |
//! | backward launches | compositing backward, projection backward, background reduction | the same, the compositing backward once per batch |
//! | largest buffer | `2^L` entries of 4 B (4 GiB past `2^29`: beyond wgpu's limit) | `I_batch` entries of 4 B, `I_batch` capped by the device's buffer limit |
//!
//! Device memory of the sort, per intersection of a batch: keys, depth bits and payloads, each double
//! buffered (`6 · 4 = 24` B) while sorting by depth, `4 · 4 = 16` B while sorting by list, and `16 / 1024 · 4`
//! B of histogram; after the forward only the sorted Gaussian ids (4 B per intersection) stay alive.
//!
//! Everything stays on the device; the saved state ([`CubeForward`]) holds device buffers only. Kernels bind at
//! most 13 storage buffers (the compositing backward adds into one buffer holding all its gradients), within
//! what wgpu adapters offer.
//!
//! Lavapipe (Mesa 22.3, the software Vulkan of the CI machine) cannot compile the shared memory CubeCL 0.11.3
//! emits as SPIR-V for devices without Vulkan's explicit workgroup layout (it crashes in pipeline creation);
//! through WGSL (the `wgpu` feature, which the tests use) it runs the shared memory of every kernel that has
//! some: compositing, and the scan and sort, which work cooperatively on tiles, one cube each. The `vulkan`
//! (SPIR-V) feature's shared-memory kernels are checked on a GPU.
//!
//! Against the host implementation: the images agree to float rounding (the host projects in `f64`, these
//! kernels in `f32`, and accumulation orders differ under atomics), so the GPU path is tested against the host
//! with tolerances, not bit for bit. A footprint radius or tile boundary that falls within rounding of an
//! integer can differ by one between the two, which changes `tile_intersections` (never a pixel value).

mod args;
mod bin;
mod composite;
mod composite_backward;
mod lists;
mod math;
mod probe;
mod project;
mod project_backward;
mod radix;
mod scan;
mod stage;
mod timing;

use std::fmt;
use std::sync::Arc;

use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{DType, Shape, TensorMetadata};
use burn::tensor::Slice;
use burn_cubecl::cubecl::features::Plane;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::cubecl::{self, calculate_cube_count_elemwise};
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::ops::numeric::{empty_device_dtype, zeros_client};
use burn_cubecl::tensor::CubeTensor;
use burn_cubecl::{CubeBackend, CubeDevice};
use dggt_geom::ImageSize;

use super::{PACKED_EXTRA_CHANNELS, SplatGrads, SplatInputs, SplatKernels, SplatOutputs};
use crate::cull::CullStats;
use crate::settings::{DepthStatistic, RasterSettings};
use args::{BlendInputsLaunch, GridLaunch};
use composite_backward::GradientSum;
use dggt_cube::atomic::{FloatAtomics, NativeAdd, SwapAdd};
use lists::{FootprintBuffers, ListBatch};
pub use probe::{SortedIntersections, prefix_sums, sort_intersections};
use timing::StageClock;

/// Units per cube of the per-element kernels.
const ELEMENT_UNITS: u32 = 256;
/// Shared memory a compositing cube stages footprints in, at most: WebGPU's guaranteed workgroup storage.
const SHARED_STAGE_BYTES: usize = 16 * 1024;

/// Sizes and settings of one call.
#[derive(Debug, Clone, Copy)]
struct Layout {
    views: usize,
    count: usize,
    channels: usize,
    width: u32,
    height: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    per_view: bool,
    near: f32,
    far: f32,
    eps2d: f32,
    depth: DepthStatistic,
}

impl Layout {
    fn tiles(&self) -> usize {
        (self.tiles_x * self.tiles_y) as usize
    }

    fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    fn pairs(&self) -> usize {
        self.views * self.count
    }

    /// The sizes as the kernels read them, for every launch that needs them.
    fn grid(&self) -> GridLaunch {
        GridLaunch::new(
            self.count as u32,
            self.views as u32,
            self.per_view as u32,
            self.width,
            self.height,
            self.tile_size,
            self.tiles_x,
            self.tiles_y,
        )
    }
}

/// What the backward pass reads, all on the device: the contiguous inputs, the projection (`[V, N, ..]`), the
/// sorted tile lists and the per-pixel results of compositing.
///
/// Memory, for `N` Gaussians with `K` channels, `V` views of `P` pixels, `T` tiles a view and `I` tile
/// intersections, besides the inputs (kept as given, copied only where not contiguous):
///
/// - per (view, Gaussian) pair, 28 bytes: mean (8), conic (12), depth (4) and culling code (4);
/// - per intersection, 4 bytes: the sorted Gaussian id (no padding);
/// - per tile list, 8 bytes: its range;
/// - per pixel, `4 (K + 2)` bytes of packed image (the output itself, shared), 4 of final transmittance and
///   4 of list end.
///
/// At 2.2M Gaussians, 12 views of 518x350 (`T = 726`, `P = 181 300`), `K = 3`: 739 MB of pairs, `4 I` bytes of
/// ids, 70 kB of ranges and 61 MB of pixels (44 MB of them the output images).
#[derive(Clone)]
pub struct CubeForward {
    layout: Layout,
    means: CubeTensor,
    quats: CubeTensor,
    scales: CubeTensor,
    opacities: CubeTensor,
    colors: CubeTensor,
    background: CubeTensor,
    viewmats: CubeTensor,
    intrinsics: CubeTensor,
    means2d: CubeTensor,
    conics: CubeTensor,
    depths: CubeTensor,
    reasons: CubeTensor,
    batches: Vec<ListBatch>,
    images: CubeTensor,
    transmittance: CubeTensor,
    list_ends: CubeTensor,
}

impl fmt::Debug for CubeForward {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CubeForward").field("layout", &self.layout).finish_non_exhaustive()
    }
}

fn buffer(device: &CubeDevice, len: usize, dtype: DType) -> CubeTensor {
    empty_device_dtype(device.client(), device.clone(), Shape::new([len.max(1)]), dtype)
}

fn zeroed(device: &CubeDevice, len: usize, dtype: DType) -> CubeTensor {
    zeros_client(device.client(), device.clone(), Shape::new([len.max(1)]), dtype)
}

fn arg(tensor: &CubeTensor) -> TensorArg {
    tensor.clone().into_tensor_arg()
}

/// Checks an input and makes it contiguous, so kernels index it linearly.
fn contiguous(tensor: CubeTensor, what: &str) -> CubeTensor {
    assert_eq!(tensor.dtype, DType::F32, "splat: `{what}` must be an f32 tensor, got {:?}", tensor.dtype);
    into_contiguous(tensor)
}

/// What both compositing passes read for `batch`: its lists, the pairs' footprints (`means2d`, `conics`,
/// `depths`) and the Gaussians' opacities, colours and background (see `args::BlendInputs`).
fn blend_inputs(
    batch: &ListBatch,
    [means2d, conics, depths]: [&CubeTensor; 3],
    [opacities, colors, background]: [&CubeTensor; 3],
) -> BlendInputsLaunch {
    BlendInputsLaunch::new(
        arg(&batch.ids),
        arg(&batch.ranges),
        arg(means2d),
        arg(conics),
        arg(depths),
        arg(opacities),
        arg(colors),
        arg(background),
    )
}

fn element_launch(client: &cubecl::client::Client, elements: usize) -> (CubeCount, CubeDim) {
    let dim = CubeDim::new_1d(ELEMENT_UNITS);
    (calculate_cube_count_elemwise(client, elements, dim), dim)
}

/// `cubes` cubes of `units` units, spread over two dimensions where one would pass the device's limit (kernels
/// read their index as `CUBE_POS` and mask the idle cubes past `cubes`).
fn cube_launch(client: &cubecl::client::Client, cubes: usize, units: u32) -> (CubeCount, CubeDim) {
    let dim = CubeDim::new_1d(units);
    (calculate_cube_count_elemwise(client, cubes * units as usize, dim), dim)
}

/// One cube per tile of a batch's views and tile rows, one unit per pixel of the tile.
fn tile_launch(layout: &Layout, batch: &ListBatch) -> (CubeCount, CubeDim) {
    (
        CubeCount::new_3d(layout.tiles_x, batch.rows.len() as u32, batch.views as u32),
        CubeDim::new_2d(layout.tile_size, layout.tile_size),
    )
}

/// How many footprints a compositing cube stages in shared memory at a time: one per unit, fewer when they
/// would pass [`SHARED_STAGE_BYTES`] (4 bytes each for the Gaussian's index, mean (2), conic (3), opacity, depth
/// and the colours: `stage::FootprintStage`).
fn stage_len(layout: &Layout) -> u32 {
    let bytes_per_footprint = 4 * (8 + layout.channels);
    let units = layout.tile_size * layout.tile_size;
    units.min((SHARED_STAGE_BYTES / bytes_per_footprint).max(1) as u32)
}

/// How the compositing backward sums its units' gradients: across each plane where the device has plane
/// operations, unless the environment variable `DGGT_SPLAT_UNIT_SUMS` is set (to test the other path on any
/// device).
fn gradient_sum(client: &cubecl::client::Client) -> GradientSum {
    if std::env::var_os("DGGT_SPLAT_UNIT_SUMS").is_none() && client.properties().features.plane.contains(Plane::Ops) {
        GradientSum::PerPlane
    } else {
        GradientSum::PerUnit
    }
}

/// Whether the backward pass adds gradients with native `f32` atomics: when the device supports them, unless
/// the environment variable `DGGT_SPLAT_CAS_ATOMICS` is set (to test the compare-and-swap path on any device).
fn native_float_atomics(client: &cubecl::client::Client) -> bool {
    std::env::var_os("DGGT_SPLAT_CAS_ATOMICS").is_none() && FloatAtomics::of(client) == FloatAtomics::Native
}

fn layout(inputs: &SplatInputs<CubeBackend>, settings: &RasterSettings, size: ImageSize) -> Layout {
    let count = inputs.means.shape()[0];
    let views = inputs.viewmats.shape()[0];
    let channels = inputs.colors.shape()[1];
    let tile_size = settings.tile_size;
    assert!(tile_size > 0, "splat: tile_size must be positive");
    assert!(channels > 0, "splat: colours need at least one channel");
    Layout {
        views,
        count,
        channels,
        width: size.width,
        height: size.height,
        tile_size,
        tiles_x: size.width.div_ceil(tile_size),
        tiles_y: size.height.div_ceil(tile_size),
        per_view: inputs.opacities.shape().num_dims() == 2,
        near: settings.near_plane,
        far: settings.far_plane,
        eps2d: settings.eps2d,
        depth: settings.depth,
    }
}

/// The per-(view, Gaussian) footprints of the projection, with the per-list intersection counts and the
/// culling statistics.
struct Footprints {
    means2d: CubeTensor,
    conics: CubeTensor,
    depths: CubeTensor,
    radii: CubeTensor,
    reasons: CubeTensor,
    pair_counts: CubeTensor,
    stats: CubeTensor,
}

/// What compositing writes: the packed images, the final transmittance and each pixel's list end.
struct Composited {
    images: CubeTensor,
    transmittance: CubeTensor,
    list_ends: CubeTensor,
}

/// Every input made contiguous, so the kernels index it linearly.
fn contiguous_inputs(inputs: SplatInputs<CubeBackend>) -> SplatInputs<CubeBackend> {
    SplatInputs {
        means: contiguous(inputs.means, "means"),
        quats: contiguous(inputs.quats, "quats"),
        scales: contiguous(inputs.scales, "scales"),
        opacities: contiguous(inputs.opacities, "opacities"),
        colors: contiguous(inputs.colors, "colors"),
        background: contiguous(inputs.background, "background"),
        viewmats: contiguous(inputs.viewmats, "viewmats"),
        intrinsics: contiguous(inputs.intrinsics, "intrinsics"),
    }
}

/// Projects and culls every (view, Gaussian) pair, then counts the tiles each kept footprint touches.
fn project_and_count(device: &CubeDevice, layout: &Layout, inputs: &SplatInputs<CubeBackend>) -> Footprints {
    let client = device.client();
    let (views, pairs) = (layout.views, layout.pairs());
    let footprints = Footprints {
        means2d: buffer(device, 2 * pairs, DType::F32),
        conics: buffer(device, 3 * pairs, DType::F32),
        depths: buffer(device, pairs, DType::F32),
        radii: buffer(device, 2 * pairs, DType::U32),
        reasons: buffer(device, pairs, DType::U32),
        pair_counts: buffer(device, pairs, DType::U32),
        stats: zeros_client(client.clone(), device.clone(), Shape::new([views, CullStats::COUNTS]), DType::I32),
    };
    if pairs == 0 {
        return footprints;
    }
    let (cubes, dim) = element_launch(&client, pairs);
    project::project_kernel::launch(
        &client,
        cubes.clone(),
        dim,
        arg(&inputs.means),
        arg(&inputs.quats),
        arg(&inputs.scales),
        arg(&inputs.opacities),
        arg(&inputs.colors),
        arg(&inputs.viewmats),
        arg(&inputs.intrinsics),
        arg(&footprints.means2d),
        arg(&footprints.conics),
        arg(&footprints.depths),
        arg(&footprints.radii),
        arg(&footprints.reasons),
        layout.grid(),
        layout.near,
        layout.far,
        layout.eps2d,
        layout.channels,
    );
    bin::count_kernel::launch(
        &client,
        cubes,
        dim,
        arg(&footprints.means2d),
        arg(&footprints.radii),
        arg(&footprints.reasons),
        arg(&footprints.pair_counts),
        arg(&footprints.stats),
        layout.grid(),
    );
    footprints
}

/// The output buffers of compositing, for all views.
fn composited_buffers(device: &CubeDevice, layout: &Layout) -> Composited {
    let pixels = layout.views * layout.pixels();
    let stride = layout.channels + PACKED_EXTRA_CHANNELS;
    let images_shape = Shape::new([layout.views, layout.height as usize, layout.width as usize, stride]);
    Composited {
        images: empty_device_dtype(device.client(), device.clone(), images_shape, DType::F32),
        transmittance: buffer(device, pixels, DType::F32),
        list_ends: buffer(device, pixels, DType::U32),
    }
}

/// Blends every pixel of a batch's views front to back.
fn composite_batch(
    device: &CubeDevice,
    layout: &Layout,
    inputs: &SplatInputs<CubeBackend>,
    footprints: &Footprints,
    batch: &ListBatch,
    out: &Composited,
) {
    let client = device.client();
    let (cubes, dim) = tile_launch(layout, batch);
    let stage = stage_len(layout);
    let pairs = [&footprints.means2d, &footprints.conics, &footprints.depths];
    let gaussians = [&inputs.opacities, &inputs.colors, &inputs.background];
    composite::composite_kernel::launch(
        &client,
        cubes,
        dim,
        blend_inputs(batch, pairs, gaussians),
        arg(&out.images),
        arg(&out.transmittance),
        arg(&out.list_ends),
        layout.grid(),
        batch.first_view as u32,
        batch.rows.start,
        stage,
        layout.channels,
        layout.depth == DepthStatistic::Median,
    );
}

/// Sorts the tile lists batch by batch (see `lists`) and composites each batch as soon as it is sorted, so
/// only one batch's intersection buffers are alive at a time besides the sorted ids kept for the backward.
fn sort_and_composite(
    device: &CubeDevice,
    layout: &Layout,
    settings: &RasterSettings,
    inputs: &SplatInputs<CubeBackend>,
    footprints: &Footprints,
    out: &Composited,
    clock: &mut StageClock,
) -> Vec<ListBatch> {
    if layout.views == 0 || layout.pixels() == 0 {
        return Vec::new();
    }
    let pair_offsets = scan::exclusive_scan(device, &footprints.pair_counts, layout.pairs());
    let starts = lists::view_starts(device, layout, &pair_offsets);
    clock.mark(|| "pair scan".into());
    let per_view = lists::per_view_counts(&starts);
    let cap = lists::max_entries(lists::buffer_cap(&device.client(), settings));
    let f = FootprintBuffers {
        means2d: &footprints.means2d,
        radii: &footprints.radii,
        reasons: &footprints.reasons,
        depths: &footprints.depths,
        pair_offsets: &pair_offsets,
    };
    let mut batches = Vec::new();
    let mut composite = |batch: ListBatch, clock: &mut StageClock| {
        composite_batch(device, layout, inputs, footprints, &batch, out);
        clock.mark(|| format!("views {}.. rows {:?} composite", batch.first_view, batch.rows));
        batches.push(batch);
    };
    let all_rows = 0..layout.tiles_y;
    for views in lists::plan_batches(&per_view, cap) {
        let entries: u64 = per_view[views.clone()].iter().sum();
        if entries <= cap {
            let base = starts[views.start];
            let batch = lists::sorted_batch(device, layout, &f, views, all_rows.clone(), base, entries as usize, clock);
            composite(batch, clock);
            continue;
        }
        // One view beyond the cap: its tile rows in bands.
        let view = views.start;
        for (rows, entries) in lists::view_bands(device, layout, &f, view, cap) {
            let batch = lists::sorted_band(device, layout, &f, view, rows, entries, clock);
            composite(batch, clock);
        }
    }
    batches
}

/// The forward pass: projection and tile counts, pair offsets, sorted tile lists and compositing batch by
/// batch; returns the outputs and what the backward pass needs.
fn forward_saved(
    inputs: SplatInputs<CubeBackend>,
    settings: &RasterSettings,
    size: ImageSize,
) -> (SplatOutputs<CubeBackend>, CubeForward) {
    let layout = layout(&inputs, settings, size);
    let device = inputs.means.device.clone();
    let mut clock = StageClock::start(&device.client(), || format!("forward {}x{}", layout.count, layout.views));
    let inputs = contiguous_inputs(inputs);
    let footprints = project_and_count(&device, &layout, &inputs);
    clock.mark(|| "project+count".into());
    let composited = composited_buffers(&device, &layout);
    let batches = sort_and_composite(&device, &layout, settings, &inputs, &footprints, &composited, &mut clock);
    let SplatInputs { means, quats, scales, opacities, colors, background, viewmats, intrinsics } = inputs;
    let Footprints { means2d, conics, depths, reasons, stats, .. } = footprints;
    let saved = CubeForward {
        layout,
        means,
        quats,
        scales,
        opacities,
        colors,
        background,
        viewmats,
        intrinsics,
        means2d,
        conics,
        depths,
        reasons,
        batches,
        images: composited.images.clone(),
        transmittance: composited.transmittance,
        list_ends: composited.list_ends,
    };
    (SplatOutputs { images: composited.images, stats }, saved)
}

/// The `f32` gradient buffers the backward kernels add into, zeroed, sized like `shape`.
fn gradient(device: &CubeDevice, shape: Shape) -> CubeTensor {
    zeros_client(device.client(), device.clone(), shape, DType::F32)
}

/// Adds the compositing gradients of a batch's views into `accumulated` (layout: `composite_backward_kernel`).
fn composite_backward_batch(
    saved: &CubeForward,
    batch: &ListBatch,
    grad_images: &CubeTensor,
    accumulated: &CubeTensor,
    native: bool,
) {
    let layout = &saved.layout;
    let client = saved.means.client.clone();
    let (cubes, dim) = tile_launch(layout, batch);
    let stage = stage_len(layout);
    let launch = if native {
        composite_backward::composite_backward_kernel::launch::<NativeAdd>
    } else {
        composite_backward::composite_backward_kernel::launch::<SwapAdd>
    };
    let pairs = [&saved.means2d, &saved.conics, &saved.depths];
    let gaussians = [&saved.opacities, &saved.colors, &saved.background];
    launch(
        &client,
        cubes,
        dim,
        blend_inputs(batch, pairs, gaussians),
        arg(&saved.images),
        arg(&saved.transmittance),
        arg(&saved.list_ends),
        arg(grad_images),
        arg(accumulated),
        layout.grid(),
        batch.first_view as u32,
        batch.rows.start,
        stage,
        layout.channels,
        gradient_sum(&client),
    );
}

fn backward(saved: &CubeForward, grad_images: FloatTensor<CubeBackend>) -> SplatGrads<CubeBackend> {
    let layout = saved.layout;
    let device = saved.means.device.clone();
    let client = device.client();
    let (views, count, channels) = (layout.views, layout.count, layout.channels);
    let pairs = layout.pairs();
    let pixels = views * layout.pixels();
    let mut clock = StageClock::start(&client, || format!("backward {count}x{views}"));
    let grad_images = contiguous(grad_images, "image gradient");

    // One buffer for everything the compositing backward adds into (see `composite_backward_kernel`).
    let opacity_len = if layout.per_view { views * count } else { count };
    let (opacity_offset, color_offset) = (6 * pairs, 6 * pairs + opacity_len);
    let accumulated = zeroed(&device, color_offset + count * channels, DType::F32);
    let grad_means = gradient(&device, Shape::new([count, 3]));
    let grad_quats = gradient(&device, Shape::new([count, 4]));
    let grad_scales = gradient(&device, Shape::new([count, 3]));

    if pixels > 0 && count > 0 {
        let native = native_float_atomics(&client);
        clock.mark(|| "zeroed gradients".into());
        for batch in &saved.batches {
            composite_backward_batch(saved, batch, &grad_images, &accumulated, native);
            clock.mark(|| format!("views {}.. composite backward", batch.first_view));
        }
        let (cubes, dim) = element_launch(&client, count);
        project_backward::project_backward_kernel::launch(
            &client,
            cubes,
            dim,
            arg(&saved.means),
            arg(&saved.quats),
            arg(&saved.scales),
            arg(&saved.viewmats),
            arg(&saved.intrinsics),
            arg(&saved.reasons),
            arg(&accumulated),
            arg(&grad_means),
            arg(&grad_quats),
            arg(&grad_scales),
            layout.grid(),
            layout.eps2d,
        );
        clock.mark(|| "project backward".into());
    }
    let part = |start: usize, len: usize, shape: Shape| {
        let slice = CubeBackend::float_slice(accumulated.clone(), &[Slice::from(start..start + len)]);
        into_contiguous(CubeBackend::float_reshape(slice, shape))
    };
    let opacity_shape = if layout.per_view { Shape::new([views, count]) } else { Shape::new([count]) };
    let grad_opacities = part(opacity_offset, opacity_len, opacity_shape);
    let grad_colors = part(color_offset, count * channels, Shape::new([count, channels]));

    let background = if pixels > 0 {
        // dL/dbg = Σ_pixels dL/dcolour · T_final.
        let stride = channels + PACKED_EXTRA_CHANNELS;
        let flat = CubeBackend::float_reshape(grad_images, Shape::new([pixels, stride]));
        let colour_grads = CubeBackend::float_slice(flat, &[Slice::from(0..pixels), Slice::from(0..channels)]);
        let transmittance = CubeBackend::float_reshape(saved.transmittance.clone(), Shape::new([pixels, 1]));
        let weighted = CubeBackend::float_mul(colour_grads, transmittance);
        CubeBackend::float_reshape(CubeBackend::float_sum_dim(weighted, 0), Shape::new([channels]))
    } else {
        gradient(&device, Shape::new([channels]))
    };

    SplatGrads {
        means: grad_means,
        quats: grad_quats,
        scales: grad_scales,
        opacities: grad_opacities,
        colors: grad_colors,
        background,
    }
}

impl SplatKernels for CubeBackend {
    type Saved = Arc<CubeForward>;

    fn splat_forward_saved(
        inputs: SplatInputs<Self>,
        settings: &RasterSettings,
        size: ImageSize,
    ) -> (SplatOutputs<Self>, Self::Saved) {
        let (outputs, saved) = forward_saved(inputs, settings, size);
        (outputs, Arc::new(saved))
    }

    fn splat_backward(saved: Self::Saved, grad_images: FloatTensor<Self>) -> SplatGrads<Self> {
        backward(&saved, grad_images)
    }
}
