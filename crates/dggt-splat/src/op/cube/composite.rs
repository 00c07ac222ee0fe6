//! Compositing: each pixel's sorted list blended front to back into colour, alpha and expected depth, with the
//! early stop at the transmittance floor.

use burn_cubecl::cubecl;
use cubecl::prelude::*;

use crate::constants::{ALPHA_THRESHOLD, MAX_ALPHA, MIN_DEPTH_ALPHA, MIN_TRANSMITTANCE};

/// Front-to-back compositing, one unit per pixel (`ABSOLUTE_POS_X/Y` the pixel, `ABSOLUTE_POS_Z` the view).
///
/// Writes the packed image `[V, H, W, K + 2]` (colours, alpha, expected depth), the final transmittance and the
/// list end per pixel.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn composite_kernel(
    ids: &Tensor<u32>,
    ranges: &Tensor<u32>,
    means2d: &Tensor<f32>,
    conics: &Tensor<f32>,
    depths: &Tensor<f32>,
    opacities: &Tensor<f32>,
    colors: &Tensor<f32>,
    background: &Tensor<f32>,
    images: &mut Tensor<f32>,
    transmittances: &mut Tensor<f32>,
    list_ends: &mut Tensor<u32>,
    count: u32,
    first_view: u32,
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
    let list = batch_view * (tiles_x * tiles_y) as usize + ((y / tile_size) * tiles_x + x / tile_size) as usize;
    let start = ranges[2 * list] as usize;
    let end = ranges[2 * list + 1] as usize;
    let base = v * count as usize;
    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);

    let mut accumulated = Array::<f32>::new(channels);
    for ch in 0..channels {
        accumulated[ch] = 0.0;
    }
    let mut depth = 0.0f32;
    let mut transmittance = 1.0f32;
    let mut last = 0u32;
    let mut j = start;
    loop {
        if j >= end {
            break;
        }
        let id = ids[j] as usize;
        let k = base + id;
        let mut opacity = opacities[id];
        if per_view == 1 {
            opacity = opacities[k];
        }
        let dx = means2d[2 * k] - px;
        let dy = means2d[2 * k + 1] - py;
        let (a, b, c) = (conics[3 * k], conics[3 * k + 1], conics[3 * k + 2]);
        let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
        let alpha = (opacity * (-sigma).exp()).min(MAX_ALPHA);
        if !(sigma.is_nan() || sigma < 0.0 || alpha < ALPHA_THRESHOLD) {
            let next = transmittance * (1.0 - alpha);
            if next <= MIN_TRANSMITTANCE {
                break;
            }
            let weight = alpha * transmittance;
            for ch in 0..channels {
                accumulated[ch] += colors[id * channels + ch] * weight;
            }
            depth += depths[k] * weight;
            transmittance = next;
            last = (j - start + 1) as u32;
        }
        j += 1;
    }
    let alpha = 1.0 - transmittance;
    let out = pixel * (channels + 2);
    for ch in 0..channels {
        images[out + ch] = accumulated[ch] + transmittance * background[ch];
    }
    images[out + channels] = alpha;
    images[out + channels + 1] = depth / alpha.max(MIN_DEPTH_ALPHA);
    transmittances[pixel] = transmittance;
    list_ends[pixel] = last;
}
