//! The backward pass of compositing: each tile's list walked back to front, each footprint's gradient (mean,
//! conic, depth, opacity, colour) added into one shared buffer.
//!
//! One cube per tile, one unit per pixel, as in the forward pass: the footprints are staged through shared
//! memory `stage` at a time, from the end of the tile's longest pixel list backwards; every unit computes its
//! pixel's contribution to each staged footprint in the same back-to-front order as the host. With plane
//! operations the contributions are summed across each plane (`plane_sum`) and one unit of the plane adds the
//! sum, one atomic per footprint and plane instead of one per pixel; without them every unit adds its own. A
//! footprint that no unit of the plane (or, without plane operations, the unit itself) blended adds nothing.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use super::args::{BlendInputs, Grid};
use super::composite::tile_pixel;
use super::stage::{FootprintStage, footprint_at, load_footprint};
use crate::constants::{MAX_ALPHA, MIN_DEPTH_ALPHA};
use dggt_cube::atomic::FloatAdd;

/// How the units of a cube add their gradients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GradientSum {
    /// Summed over each plane first; one add per plane. Every unit of the cube calls the add.
    PerPlane,
    /// One add per unit (devices without plane operations).
    PerUnit,
}

/// Whether a footprint's gradients are added at all: when any unit of the plane blended it (every unit of the
/// plane then takes the plane's sums), or, one add per unit, when this unit did. A footprint that no unit blended
/// would add only zeros: most footprints of a tile's list cover a few of its pixels, so most adds are skipped.
#[cube]
fn adds_gradients(blended: bool, #[comptime] sum: GradientSum) -> bool {
    let mut adds = blended;
    if comptime!(sum == GradientSum::PerPlane) {
        adds = plane_any(blended);
    }
    adds
}

/// `grads[index] += value`, summed per [`GradientSum`].
#[cube]
fn add_gradient<A: FloatAdd>(grads: &Tensor<Atomic<A::Slot>>, index: usize, value: f32, #[comptime] sum: GradientSum) {
    if comptime!(sum == GradientSum::PerPlane) {
        let total = plane_sum(value);
        if UNIT_POS_PLANE == 0 {
            A::add(grads, index, total);
        }
    } else {
        A::add(grads, index, value);
    }
}

/// The loss's gradients at one pixel's outputs, as the walk back needs them.
#[derive(CubeType)]
struct PixelGrads {
    /// `dL/dcolour` per channel.
    colors: Array<f32>,
    /// `dL/d(Σ w·depth)`: the expected depth divides by the (clamped) alpha.
    sum_depth: f32,
    /// `dL/dT_final`: through the background and the alpha `1 - T_final`.
    final_transmittance: f32,
    /// `T_final`.
    transmittance: f32,
}

/// The output gradients of `pixel` (zeros for a pixel that blended nothing or lies outside the image).
#[cube]
fn pixel_grads(
    images: &Tensor<f32>,
    transmittances: &Tensor<f32>,
    grad_images: &Tensor<f32>,
    background: &Tensor<f32>,
    pixel: usize,
    blended_any: bool,
    #[comptime] channels: usize,
) -> PixelGrads {
    let mut colors = Array::<f32>::new(channels);
    for ch in 0..channels {
        colors[ch] = 0.0;
    }
    let mut grads = PixelGrads { colors, sum_depth: 0.0, final_transmittance: 0.0, transmittance: 1.0 };
    if blended_any {
        let packed = pixel * (channels + 2);
        grads.transmittance = transmittances[pixel];
        let alpha_out = images[packed + channels];
        let depth_out = images[packed + channels + 1];
        let grad_depth_out = grad_images[packed + channels + 1];
        // depth = D / max(alpha, eps): dD = g / max(alpha, eps); dalpha -= g depth / alpha (unless clamped).
        let clamped_alpha = alpha_out.max(MIN_DEPTH_ALPHA);
        grads.sum_depth = grad_depth_out / clamped_alpha;
        let mut grad_alpha_out = grad_images[packed + channels];
        if alpha_out >= MIN_DEPTH_ALPHA {
            grad_alpha_out -= grad_depth_out * depth_out / clamped_alpha;
        }
        let mut grad_final = -grad_alpha_out;
        for ch in 0..channels {
            let g = grad_images[packed + ch];
            grads.colors[ch] = g;
            grad_final += g * background[ch];
        }
        grads.final_transmittance = grad_final;
    }
    grads
}

/// Backward of compositing, one cube per tile and one unit per pixel (as `composite_kernel`): walks the tile's
/// list back to front from the end of its longest pixel list and adds each footprint's gradient into one
/// buffer holding, in this order, the per-(view, Gaussian) gradients of `means2d [V, N, 2]`, `conics [V, N, 3]`
/// and `depths [V, N]`, then the input gradients of the opacities (`[N]` or `[V, N]`, from `6 V N`) and
/// the colours (`[N, K]`, after the opacities). One buffer keeps the kernel within the
/// storage-buffer bindings every wgpu adapter offers.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn composite_backward_kernel<A: FloatAdd>(
    inputs: &BlendInputs,
    images: &Tensor<f32>,
    transmittances: &Tensor<f32>,
    list_ends: &Tensor<u32>,
    grad_images: &Tensor<f32>,
    grads: &Tensor<Atomic<A::Slot>>,
    grid: Grid,
    first_view: u32,
    first_row: u32,
    #[comptime] stage: u32,
    #[comptime] channels: usize,
    #[comptime] sum: GradientSum,
) {
    let slots = comptime!(stage as usize);
    let t = tile_pixel(&grid, &inputs.ranges, first_view, first_row);
    let (start, base, pixel) = (t.start, t.base, t.pixel);
    let mut last = 0u32;
    if t.inside {
        last = list_ends[pixel];
    }
    let longest = Shared::<[Atomic<u32>]>::new_slice(1usize);
    if UNIT_POS == 0 {
        longest[0].store(0u32);
    }
    sync_cube();
    longest[0].fetch_max(last);
    let tile_last = workgroup_uniform_load_atomic(&longest[0]);

    // The sections of `grads`, in order: means, conics, depths, opacities, colours.
    let pairs = grid.views as usize * grid.count as usize;
    let conic_offset = 2 * pairs;
    let depth_offset = 5 * pairs;
    let opacity_offset = 6 * pairs;
    let mut color_offset = opacity_offset + grid.count as usize;
    if grid.per_view == 1 {
        color_offset = opacity_offset + pairs;
    }

    let out = pixel_grads(images, transmittances, grad_images, &inputs.background, pixel, last > 0, channels);
    let mut behind = Array::<f32>::new(channels);
    for ch in 0..channels {
        behind[ch] = 0.0;
    }
    let mut depth_behind = 0.0f32;
    let mut transmittance = out.transmittance;

    let mut staged = FootprintStage::new(slots, channels);

    // Entries `[start, batch_end)` remain; each batch stages the last `stage` of them, slot 0 the backmost.
    let mut batch_end = start + tile_last;
    loop {
        if batch_end <= start {
            break;
        }
        let batch = (batch_end - start).min(stage);
        let slot = UNIT_POS as usize;
        // Every unit is done with the previous batch before it is overwritten.
        sync_cube();
        if UNIT_POS < batch {
            let e = (batch_end - 1 - UNIT_POS) as usize;
            load_footprint(&mut staged, slot, inputs, e, base, grid.per_view, channels);
        }
        sync_cube();
        for i in 0..batch {
            let s = i as usize;
            let id = staged.ids[s] as usize;
            let k = base + id;
            let mut opacity_slot = id;
            if grid.per_view == 1 {
                opacity_slot = k;
            }
            // This pixel blended entry `batch_end - 1 - i` only if it lies before its own list end.
            let entry = batch_end - 1 - i;
            let f = footprint_at(&staged, s, t.px, t.py);
            let (dx, dy, a, b, c, alpha) = (f.dx, f.dy, f.a, f.b, f.c, f.alpha);
            let blended = entry < start + last && f.visible;
            // Zero unless blended, so that a footprint this pixel did not blend adds nothing (not even a
            // NaN from an extreme offset times a zero gradient).
            let mut grad_colors = Array::<f32>::new(channels);
            for ch in 0..channels {
                grad_colors[ch] = 0.0;
            }
            let mut grad_depth = 0.0f32;
            let mut grad_opacity = 0.0f32;
            let mut grad_conic = Array::<f32>::new(3usize);
            let mut grad_mean = Array::<f32>::new(2usize);
            for e in 0..3usize {
                grad_conic[e] = 0.0;
            }
            grad_mean[0] = 0.0;
            grad_mean[1] = 0.0;
            if blended {
                let remaining = 1.0 - alpha;
                transmittance /= remaining;
                let weight = alpha * transmittance;
                let mut grad_alpha = 0.0f32;
                for ch in 0..channels {
                    let color = staged.colors[channels * s + ch];
                    grad_colors[ch] = out.colors[ch] * weight;
                    grad_alpha += out.colors[ch] * (color - behind[ch]);
                    behind[ch] = alpha * color + remaining * behind[ch];
                }
                let depth = staged.depths[s];
                grad_depth = out.sum_depth * weight;
                grad_alpha += out.sum_depth * (depth - depth_behind);
                depth_behind = alpha * depth + remaining * depth_behind;
                grad_alpha = grad_alpha * transmittance - out.final_transmittance * out.transmittance / remaining;
                if f.raw <= MAX_ALPHA {
                    grad_opacity = grad_alpha * f.falloff;
                    // alpha = o exp(-sigma): dalpha/dsigma = -alpha.
                    let grad_sigma = -grad_alpha * alpha;
                    grad_conic[0] = grad_sigma * 0.5 * dx * dx;
                    grad_conic[1] = grad_sigma * dx * dy;
                    grad_conic[2] = grad_sigma * 0.5 * dy * dy;
                    grad_mean[0] = grad_sigma * (a * dx + b * dy);
                    grad_mean[1] = grad_sigma * (b * dx + c * dy);
                }
            }
            if adds_gradients(blended, sum) {
                for ch in 0..channels {
                    add_gradient::<A>(grads, color_offset + id * channels + ch, grad_colors[ch], sum);
                }
                add_gradient::<A>(grads, depth_offset + k, grad_depth, sum);
                add_gradient::<A>(grads, opacity_offset + opacity_slot, grad_opacity, sum);
                for e in 0..3usize {
                    add_gradient::<A>(grads, conic_offset + 3 * k + e, grad_conic[e], sum);
                }
                add_gradient::<A>(grads, 2 * k, grad_mean[0], sum);
                add_gradient::<A>(grads, 2 * k + 1, grad_mean[1], sum);
            }
        }
        batch_end -= batch;
    }
}
