//! The backward pass of compositing: each pixel's list walked back to front, each footprint's gradient (mean,
//! conic, depth, opacity, colour) added into one shared buffer.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use super::math::*;
use crate::constants::{ALPHA_THRESHOLD, MAX_ALPHA, MIN_DEPTH_ALPHA};

/// Backward of compositing, one unit per pixel: walks the pixel's list back to front from its end and adds
/// each footprint's gradient into one buffer holding, in this order, the per-(view, Gaussian) gradients of
/// `means2d [V, N, 2]`, `conics [V, N, 3]` and `depths [V, N]`, then the input gradients of the opacities
/// (`[N]` or `[V, N]`, starting at `opacity_offset`) and the colours (`[N, K]`, at `color_offset`). One buffer
/// keeps the kernel within the storage-buffer bindings every wgpu adapter offers.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn composite_backward_kernel<A: FloatAdd>(
    ids: &Tensor<u32>,
    ranges: &Tensor<u32>,
    means2d: &Tensor<f32>,
    conics: &Tensor<f32>,
    depths: &Tensor<f32>,
    opacities: &Tensor<f32>,
    colors: &Tensor<f32>,
    background: &Tensor<f32>,
    images: &Tensor<f32>,
    transmittances: &Tensor<f32>,
    list_ends: &Tensor<u32>,
    grad_images: &Tensor<f32>,
    grads: &Tensor<Atomic<A::Slot>>,
    count: u32,
    first_view: u32,
    views: u32,
    opacity_offset: u32,
    color_offset: u32,
    per_view: u32,
    width: u32,
    height: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    #[comptime] channels: usize,
) {
    let x = ABSOLUTE_POS_X;
    let y = ABSOLUTE_POS_Y;
    let batch_view = ABSOLUTE_POS_Z as usize;
    let v = first_view as usize + batch_view;
    if x >= width || y >= height {
        terminate!();
    }
    let pixel = (v * height as usize + y as usize) * width as usize + x as usize;
    let last = list_ends[pixel] as usize;
    if last == 0 {
        terminate!();
    }
    let list = batch_view * (tiles_x * tiles_y) as usize + ((y / tile_size) * tiles_x + x / tile_size) as usize;
    let start = ranges[2 * list] as usize;
    let base = v * count as usize;
    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
    let packed = pixel * (channels + 2);
    let pairs = views as usize * count as usize;
    let conic_offset = 2 * pairs;
    let depth_offset = 5 * pairs;
    let opacity_offset = opacity_offset as usize;
    let color_offset = color_offset as usize;

    let final_transmittance = transmittances[pixel];
    let alpha_out = images[packed + channels];
    let depth_out = images[packed + channels + 1];
    let grad_depth_out = grad_images[packed + channels + 1];
    // depth = D / max(alpha, eps): dD = g / max(alpha, eps); dalpha -= g depth / alpha (unless clamped).
    let clamped_alpha = alpha_out.max(MIN_DEPTH_ALPHA);
    let grad_sum_depth = grad_depth_out / clamped_alpha;
    let mut grad_alpha_out = grad_images[packed + channels];
    if alpha_out >= MIN_DEPTH_ALPHA {
        grad_alpha_out -= grad_depth_out * depth_out / clamped_alpha;
    }
    let mut grad_final = -grad_alpha_out;
    for ch in 0..channels {
        grad_final += grad_images[packed + ch] * background[ch];
    }

    let mut behind = Array::<f32>::new(channels);
    for ch in 0..channels {
        behind[ch] = 0.0;
    }
    let mut depth_behind = 0.0f32;
    let mut transmittance = final_transmittance;
    let mut j = start + last;
    loop {
        if j == start {
            break;
        }
        j -= 1;
        let id = ids[j] as usize;
        let k = base + id;
        let mut opacity = opacities[id];
        let mut opacity_slot = id;
        if per_view == 1 {
            opacity = opacities[k];
            opacity_slot = k;
        }
        let dx = means2d[2 * k] - px;
        let dy = means2d[2 * k + 1] - py;
        let (a, b, c) = (conics[3 * k], conics[3 * k + 1], conics[3 * k + 2]);
        let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
        let falloff = (-sigma).exp();
        let raw = opacity * falloff;
        let alpha = raw.min(MAX_ALPHA);
        if !(sigma.is_nan() || sigma < 0.0 || alpha < ALPHA_THRESHOLD) {
            let remaining = 1.0 - alpha;
            transmittance /= remaining;
            let weight = alpha * transmittance;
            let mut grad_alpha = 0.0f32;
            for ch in 0..channels {
                let color = colors[id * channels + ch];
                let g = grad_images[packed + ch];
                A::add(grads, color_offset + id * channels + ch, g * weight);
                grad_alpha += g * (color - behind[ch]);
                behind[ch] = alpha * color + remaining * behind[ch];
            }
            let depth = depths[k];
            A::add(grads, depth_offset + k, grad_sum_depth * weight);
            grad_alpha += grad_sum_depth * (depth - depth_behind);
            depth_behind = alpha * depth + remaining * depth_behind;
            grad_alpha = grad_alpha * transmittance - grad_final * final_transmittance / remaining;
            if raw <= MAX_ALPHA {
                A::add(grads, opacity_offset + opacity_slot, grad_alpha * falloff);
                // alpha = o exp(-sigma): dalpha/dsigma = -alpha.
                let grad_sigma = -grad_alpha * alpha;
                A::add(grads, conic_offset + 3 * k, grad_sigma * 0.5 * dx * dx);
                A::add(grads, conic_offset + 3 * k + 1, grad_sigma * dx * dy);
                A::add(grads, conic_offset + 3 * k + 2, grad_sigma * 0.5 * dy * dy);
                A::add(grads, 2 * k, grad_sigma * (a * dx + b * dy));
                A::add(grads, 2 * k + 1, grad_sigma * (b * dx + c * dy));
            }
        }
    }
}
