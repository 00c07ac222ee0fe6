//! Front-to-back alpha compositing of a tile's depth-sorted footprints, and its backward pass.
//!
//! Per pixel (centre `(x + 0.5, y + 0.5)`), for each footprint in depth order: `d = mean2d - centre`,
//! `sigma = ½(a dx² + c dy²) + b dx dy`, `alpha = min(0.999, o exp(-sigma))`; skipped if `sigma < 0` or
//! `alpha < 1/255`; if the next transmittance `T (1 - alpha)` would be `<= 1e-4` the pixel stops *without*
//! this footprint; otherwise colours and depth accumulate with weight `alpha T`. Outputs: colour
//! `Σ w c + T bg`, alpha `1 - T`, expected depth `Σ w z / max(alpha, 1e-10)`, or with
//! [`DepthStatistic::Median`] the depth of the footprint that first brings `T` to one half or below (the
//! expected depth where `T` stays above one half).
//!
//! The forward runs in `f32` like a GPU kernel. It records per pixel the final transmittance and where in the
//! tile list it stopped; the backward walks the list back to front from there, recovering each `T` by division
//! by `1 - alpha` (at least 0.001), and sums per-footprint gradients over the tile's pixels in `f64`. Both
//! passes evaluate alpha with the same function, so their skip decisions agree exactly.

use crate::blocks::{BlockLists, Reach};
use crate::constants::{ALPHA_THRESHOLD, MAX_ALPHA, MEDIAN_TRANSMITTANCE, MIN_DEPTH_ALPHA, MIN_TRANSMITTANCE};
use crate::gaussians::Gaussians;
use crate::projection::Projection;
use crate::settings::DepthStatistic;
use crate::tiles::{TileBins, TileGrid};

/// Layout of one row of per-footprint gradients: `[mean2d x y, conic a b c, opacity, depth, colour 0..K]`.
pub(crate) const GRAD_MEAN2D: usize = 0;
pub(crate) const GRAD_CONIC: usize = 2;
pub(crate) const GRAD_OPACITY: usize = 5;
pub(crate) const GRAD_DEPTH: usize = 6;
pub(crate) const GRAD_COLOR: usize = 7;

/// Length of a per-footprint gradient row for `channels` colour channels.
pub(crate) fn grad_stride(channels: usize) -> usize {
    GRAD_COLOR + channels
}

/// Everything compositing reads for one view.
pub(crate) struct ViewScene<'a> {
    pub gaussians: &'a Gaussians<'a>,
    pub projection: &'a Projection,
    pub bins: &'a TileBins,
    pub grid: TileGrid,
    pub view: usize,
    pub background: &'a [f32],
    pub depth: DepthStatistic,
}

/// The output rows `[y0, y1)` of one view that one band of tiles writes, each `[rows, W, ...]`.
pub(crate) struct BandOutput<'a> {
    pub colors: &'a mut [f32],
    pub alpha: &'a mut [f32],
    pub depth: &'a mut [f32],
    pub transmittance: &'a mut [f32],
    pub list_ends: &'a mut [u32],
}

/// The forward outputs of one view that the backward reads, each `[H, W, ...]`.
pub(crate) struct ForwardPixels<'a> {
    pub alpha: &'a [f32],
    pub depth: &'a [f32],
    pub transmittance: &'a [f32],
    pub list_ends: &'a [u32],
}

/// Loss gradients of one view's outputs (`None` = zero), each `[H, W, ...]`.
pub(crate) struct PixelGrads<'a> {
    pub colors: Option<&'a [f32]>,
    pub alpha: Option<&'a [f32]>,
    pub depth: Option<&'a [f32]>,
}

/// A footprint's alpha at one pixel.
struct Coverage {
    alpha: f32,
    /// `exp(-sigma)`.
    falloff: f32,
    /// Whether the 0.999 clamp is active (then alpha has no gradient).
    saturated: bool,
    dx: f32,
    dy: f32,
}

/// The footprints of one tile, gathered into contiguous arrays in list order.
struct TileSplats {
    means2d: Vec<[f32; 2]>,
    conics: Vec<[f32; 3]>,
    opacities: Vec<f32>,
    depths: Vec<f32>,
    /// `[n, K]`.
    colors: Vec<f32>,
    /// Sigma beyond which each footprint is skipped (below the alpha threshold), tested before `exp`.
    cutoffs: Vec<f32>,
    /// Which footprints can reach each block of the tile's pixels.
    blocks: BlockLists,
}

impl TileSplats {
    fn gather(scene: &ViewScene, tile: usize) -> Self {
        let ids = scene.bins.tile(tile);
        let count = scene.gaussians.len();
        let channels = scene.gaussians.channels();
        let mut means2d = Vec::with_capacity(ids.len());
        let mut conics = Vec::with_capacity(ids.len());
        let mut opacities = Vec::with_capacity(ids.len());
        let mut depths = Vec::with_capacity(ids.len());
        let mut colors = Vec::with_capacity(ids.len() * channels);
        let mut reaches = Vec::with_capacity(ids.len());
        for &id in ids {
            let i = id as usize;
            let footprint =
                scene.projection.footprint(scene.view * count + i).expect("tile lists hold only kept Gaussians");
            let opacity = scene.gaussians.opacity(scene.view, i);
            means2d.push(footprint.mean2d);
            conics.push(footprint.conic);
            depths.push(footprint.depth);
            opacities.push(opacity);
            colors.extend_from_slice(scene.gaussians.color(i));
            reaches.push(Reach::new(footprint.conic, opacity, ALPHA_THRESHOLD));
        }
        let blocks = BlockLists::build(scene.grid.pixel_rect(tile), &means2d, &reaches);
        let cutoffs = reaches.iter().map(|r| r.cutoff).collect();
        TileSplats { means2d, conics, opacities, depths, colors, cutoffs, blocks }
    }

    /// Alpha of footprint `j` at pixel centre `(px, py)`, or `None` if it is skipped there.
    fn coverage(&self, j: usize, px: f32, py: f32) -> Option<Coverage> {
        let [mx, my] = self.means2d[j];
        let [a, b, c] = self.conics[j];
        let (dx, dy) = (mx - px, my - py);
        let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
        if sigma > self.cutoffs[j] {
            return None;
        }
        let falloff = (-sigma).exp();
        let raw = self.opacities[j] * falloff;
        let alpha = raw.min(MAX_ALPHA);
        // A NaN sigma (inf - inf from an extreme conic far from the centre) is skipped like a negative one.
        if sigma.is_nan() || sigma < 0.0 || alpha < ALPHA_THRESHOLD {
            return None;
        }
        Some(Coverage { alpha, falloff, saturated: raw > MAX_ALPHA, dx, dy })
    }
}

/// Composites tile row `tile_row` of the view into `out`.
pub(crate) fn composite_band(scene: &ViewScene, tile_row: usize, out: &mut BandOutput) {
    let grid = &scene.grid;
    let channels = scene.gaussians.channels();
    let row0 = tile_row * grid.tile_size;
    let mut accumulated = vec![0.0f32; channels];
    for tile in tile_row * grid.tiles_x..(tile_row + 1) * grid.tiles_x {
        let splats = TileSplats::gather(scene, tile);
        let [x0, x1, y0, y1] = grid.pixel_rect(tile);
        for y in y0..y1 {
            for x in x0..x1 {
                let pixel = (y - row0) * grid.width + x;
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                accumulated.fill(0.0);
                let mut depth = 0.0f32;
                let mut median_depth = None;
                let mut transmittance = 1.0f32;
                let mut end = 0usize;
                for &j in splats.blocks.at(x, y) {
                    let j = j as usize;
                    let Some(coverage) = splats.coverage(j, px, py) else { continue };
                    let next = transmittance * (1.0 - coverage.alpha);
                    if next <= MIN_TRANSMITTANCE {
                        break;
                    }
                    let weight = coverage.alpha * transmittance;
                    let color = &splats.colors[j * channels..(j + 1) * channels];
                    for (sum, c) in accumulated.iter_mut().zip(color) {
                        *sum += c * weight;
                    }
                    depth += splats.depths[j] * weight;
                    if median_depth.is_none() && next <= MEDIAN_TRANSMITTANCE {
                        median_depth = Some(splats.depths[j]);
                    }
                    transmittance = next;
                    end = j + 1;
                }
                let alpha = 1.0 - transmittance;
                let expected_depth = depth / alpha.max(MIN_DEPTH_ALPHA);
                let colors = &mut out.colors[pixel * channels..(pixel + 1) * channels];
                for ((o, sum), bg) in colors.iter_mut().zip(&accumulated).zip(scene.background) {
                    *o = sum + transmittance * bg;
                }
                out.alpha[pixel] = alpha;
                out.depth[pixel] = match scene.depth {
                    DepthStatistic::Expected => expected_depth,
                    DepthStatistic::Median => median_depth.unwrap_or(expected_depth),
                };
                out.transmittance[pixel] = transmittance;
                out.list_ends[pixel] = end as u32;
            }
        }
    }
}

/// Backward of tile `tile`: adds each listed footprint's gradient (summed over the tile's pixels) to its row
/// of `out` (`[n, grad_stride(K)]`, rows in list order), and the background gradient to `background` (`[K]`).
pub(crate) fn composite_tile_backward(
    scene: &ViewScene,
    tile: usize,
    forward: &ForwardPixels,
    grads: &PixelGrads,
    out: &mut [f64],
    background: &mut [f64],
) {
    let grid = &scene.grid;
    let channels = scene.gaussians.channels();
    let stride = grad_stride(channels);
    let splats = TileSplats::gather(scene, tile);
    let mut grad_color = vec![0.0f64; channels];
    let mut behind = vec![0.0f64; channels];
    let [x0, x1, y0, y1] = grid.pixel_rect(tile);
    for y in y0..y1 {
        for x in x0..x1 {
            let pixel = y * grid.width + x;
            let final_transmittance = forward.transmittance[pixel] as f64;
            for (k, g) in grad_color.iter_mut().enumerate() {
                *g = grads.colors.map_or(0.0, |c| c[pixel * channels + k] as f64);
            }
            for (b, g) in background.iter_mut().zip(&grad_color) {
                *b += g * final_transmittance;
            }
            let end = forward.list_ends[pixel] as usize;
            if end == 0 {
                continue;
            }
            let alpha_out = forward.alpha[pixel] as f64;
            let grad_depth_out = grads.depth.map_or(0.0, |d| d[pixel] as f64);
            // depth = D / max(alpha, eps): dD = g / max(alpha, eps); dalpha -= g depth / alpha (unless clamped).
            let clamped_alpha = alpha_out.max(MIN_DEPTH_ALPHA as f64);
            let grad_sum_depth = grad_depth_out / clamped_alpha;
            let mut grad_alpha_out = grads.alpha.map_or(0.0, |a| a[pixel] as f64);
            if alpha_out >= MIN_DEPTH_ALPHA as f64 {
                grad_alpha_out -= grad_depth_out * forward.depth[pixel] as f64 / clamped_alpha;
            }
            // Final transmittance enters through alpha = 1 - T and the background term T bg.
            let grad_final_transmittance =
                -grad_alpha_out + grad_color.iter().zip(scene.background).map(|(g, bg)| g * *bg as f64).sum::<f64>();

            let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
            let mut transmittance = final_transmittance;
            behind.fill(0.0);
            let mut depth_behind = 0.0f64;
            let reaching = splats.blocks.at(x, y);
            let listed = reaching.partition_point(|&j| (j as usize) < end);
            for &j in reaching[..listed].iter().rev() {
                let j = j as usize;
                let Some(coverage) = splats.coverage(j, px, py) else { continue };
                let alpha = coverage.alpha as f64;
                let remaining = 1.0 - alpha;
                transmittance /= remaining;
                let weight = alpha * transmittance;
                let row = &mut out[j * stride..(j + 1) * stride];
                let color = &splats.colors[j * channels..(j + 1) * channels];
                let depth = splats.depths[j] as f64;
                let mut grad_alpha = 0.0;
                for k in 0..channels {
                    let c = color[k] as f64;
                    row[GRAD_COLOR + k] += grad_color[k] * weight;
                    grad_alpha += grad_color[k] * (c - behind[k]);
                    behind[k] = alpha * c + remaining * behind[k];
                }
                row[GRAD_DEPTH] += grad_sum_depth * weight;
                grad_alpha += grad_sum_depth * (depth - depth_behind);
                depth_behind = alpha * depth + remaining * depth_behind;
                grad_alpha = grad_alpha * transmittance - grad_final_transmittance * final_transmittance / remaining;

                if coverage.saturated {
                    continue;
                }
                row[GRAD_OPACITY] += grad_alpha * coverage.falloff as f64;
                // alpha = o exp(-sigma): dalpha/dsigma = -alpha.
                let grad_sigma = -grad_alpha * alpha;
                let [a, b, c] = splats.conics[j].map(f64::from);
                let (dx, dy) = (coverage.dx as f64, coverage.dy as f64);
                row[GRAD_CONIC] += grad_sigma * 0.5 * dx * dx;
                row[GRAD_CONIC + 1] += grad_sigma * dx * dy;
                row[GRAD_CONIC + 2] += grad_sigma * 0.5 * dy * dy;
                row[GRAD_MEAN2D] += grad_sigma * (a * dx + b * dy);
                row[GRAD_MEAN2D + 1] += grad_sigma * (b * dx + c * dy);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn single(conic: [f32; 3], opacity: f32) -> TileSplats {
        let reach = Reach::new(conic, opacity, ALPHA_THRESHOLD);
        TileSplats {
            means2d: vec![[0.0, 0.0]],
            conics: vec![conic],
            opacities: vec![opacity],
            depths: vec![1.0],
            colors: vec![1.0],
            cutoffs: vec![reach.cutoff],
            blocks: BlockLists::build([0, 16, 0, 16], &[[0.0, 0.0]], &[reach]),
        }
    }

    #[test]
    fn coverage_follows_the_thresholds() {
        let splats = single([1.0, 0.0, 1.0], 0.5);
        let centre = splats.coverage(0, 0.0, 0.0).unwrap();
        assert_eq!((centre.alpha, centre.saturated), (0.5, false));
        // sigma = 0.5 * 36 = 18: alpha far below 1/255.
        assert!(splats.coverage(0, 6.0, 0.0).is_none());
        let opaque = single([1.0, 0.0, 1.0], 5.0).coverage(0, 0.0, 0.0).unwrap();
        assert_eq!((opaque.alpha, opaque.saturated), (MAX_ALPHA, true));
        // A conic that is not positive definite gives sigma < 0 away from the centre.
        assert!(single([1.0, 3.0, 1.0], 0.5).coverage(0, 1.0, -1.0).is_none());
    }

    #[test]
    fn extreme_conics_far_from_the_centre_are_skipped() {
        // a dx² and c dy² overflow to +inf, b dx dy to -inf: sigma is NaN.
        let splats = single([1e30, -1e30, 1e30], 0.9);
        assert!(splats.coverage(0, 1e5, 1e5).is_none());
        assert!(splats.coverage(0, 0.0, 0.0).is_some());
    }
}
