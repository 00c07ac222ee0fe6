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
//!
//! Both passes work on 4x4 blocks of pixels as SIMD lanes (see `lanes`): a footprint's alpha is evaluated at the
//! block's sixteen pixels at once. The forward pass composites it into every lane that is hit and has not
//! stopped; the backward pass runs its `f64` gradient pixel by pixel where it was composited, block by block in
//! row-major order, so its sums have a fixed order too.

#[cfg(test)]
use crate::blocks::Reach;
use crate::blocks::{BLOCK, BlockLists};
use crate::constants::{ALPHA_THRESHOLD, MAX_ALPHA, MEDIAN_TRANSMITTANCE, MIN_DEPTH_ALPHA, MIN_TRANSMITTANCE};
use crate::gaussians::Gaussians;
use crate::lanes::{LANES, Lanes, exp_neg, has_wide_vectors};
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

/// The pixels of one block of a tile: lane `l` is the pixel `(x0 + l % BLOCK, y0 + l / BLOCK)`; lanes past the
/// tile's (and so the image's) edge are outside and never composited.
struct BlockPixels {
    origin: [usize; 2],
    centres_x: Lanes<f32>,
    centres_y: Lanes<f32>,
    inside: Lanes<bool>,
}

impl BlockPixels {
    #[inline(always)]
    fn new(origin: [usize; 2], tile_rect: [usize; 4]) -> Self {
        let [_, x1, _, y1] = tile_rect;
        let mut pixels = Self { origin, centres_x: [0.0; LANES], centres_y: [0.0; LANES], inside: [false; LANES] };
        for l in 0..LANES {
            let (x, y) = (origin[0] + l % BLOCK, origin[1] + l / BLOCK);
            pixels.centres_x[l] = x as f32 + 0.5;
            pixels.centres_y[l] = y as f32 + 0.5;
            pixels.inside[l] = x < x1 && y < y1;
        }
        pixels
    }

    /// `(lane, x, y)` of the lanes inside the image.
    fn inside(&self) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        (0..LANES).filter(|&l| self.inside[l]).map(|l| (l, self.origin[0] + l % BLOCK, self.origin[1] + l / BLOCK))
    }
}

/// A footprint's alpha at one pixel.
struct PixelCoverage {
    alpha: f32,
    /// `exp(-sigma)`.
    falloff: f32,
    /// Whether the footprint is composited at the pixel (not skipped by the thresholds).
    hit: bool,
    /// Whether the 0.999 clamp is active (then alpha has no gradient).
    saturated: bool,
    dx: f32,
    dy: f32,
}

/// One footprint's alpha at each pixel of a block.
struct BlockCoverage {
    alpha: Lanes<f32>,
    /// `exp(-sigma)`.
    falloff: Lanes<f32>,
    /// Whether the footprint is composited at the pixel (not skipped by the thresholds).
    hit: Lanes<bool>,
    /// Whether the 0.999 clamp is active (then alpha has no gradient).
    saturated: Lanes<bool>,
    dx: Lanes<f32>,
    dy: Lanes<f32>,
}

/// The footprints of one tile, gathered into contiguous arrays in list order.
struct TileSplats {
    means2d: Vec<[f32; 2]>,
    conics: Vec<[f32; 3]>,
    opacities: Vec<f32>,
    depths: Vec<f32>,
    /// `[n, K]`.
    colors: Vec<f32>,
    /// Sigma beyond which each footprint is skipped (below the alpha threshold).
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
            let k = scene.view * count + i;
            let footprint = scene.projection.footprint(k).expect("tile lists hold only kept Gaussians");
            let opacity = scene.gaussians.opacity(scene.view, i);
            means2d.push(footprint.mean2d);
            conics.push(footprint.conic);
            depths.push(footprint.depth);
            opacities.push(opacity);
            colors.extend_from_slice(scene.gaussians.color(i));
            reaches.push(scene.projection.reaches[k]);
        }
        let blocks = BlockLists::build(scene.grid.pixel_rect(tile), &means2d, &reaches);
        let cutoffs = reaches.iter().map(|r| r.cutoff).collect();
        TileSplats { means2d, conics, opacities, depths, colors, cutoffs, blocks }
    }

    /// Footprint `j` at pixel centre `(px, py)`: the offset `mean2d - centre` and `sigma` there.
    #[inline(always)]
    fn sigma_at(&self, j: usize, px: f32, py: f32) -> (f32, f32, f32) {
        let [mx, my] = self.means2d[j];
        let [a, b, c] = self.conics[j];
        let (dx, dy) = (mx - px, my - py);
        (dx, dy, 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy)
    }

    /// Footprint `j`'s alpha at a pixel where its offset and sigma are `(dx, dy, sigma)`.
    #[inline(always)]
    fn coverage_from(&self, j: usize, (dx, dy, sigma): (f32, f32, f32)) -> PixelCoverage {
        let falloff = exp_neg(-sigma);
        let raw = self.opacities[j] * falloff;
        let alpha = raw.min(MAX_ALPHA);
        // A NaN sigma (inf - inf from an extreme conic far from the centre) fails every comparison: skipped like
        // a negative one.
        let hit = (sigma <= self.cutoffs[j]) & (sigma >= 0.0) & (alpha >= ALPHA_THRESHOLD);
        PixelCoverage { alpha, falloff, hit, saturated: raw > MAX_ALPHA, dx, dy }
    }

    /// Footprint `j`'s alpha at pixel centre `(px, py)`, or `None` if it is skipped there.
    #[cfg(test)]
    fn coverage_at(&self, j: usize, px: f32, py: f32) -> Option<PixelCoverage> {
        let offset = self.sigma_at(j, px, py);
        // Beyond the cutoff the footprint is skipped: no need for the exponential.
        if offset.2 > self.cutoffs[j] {
            return None;
        }
        Some(self.coverage_from(j, offset)).filter(|coverage| coverage.hit)
    }

    /// Footprint `j`'s alpha at the pixels of a block.
    #[inline(always)]
    fn coverage(&self, j: usize, pixels: &BlockPixels) -> BlockCoverage {
        let mut coverage = BlockCoverage {
            alpha: [0.0; LANES],
            falloff: [0.0; LANES],
            hit: [false; LANES],
            saturated: [false; LANES],
            dx: [0.0; LANES],
            dy: [0.0; LANES],
        };
        for l in 0..LANES {
            let at = self.coverage_from(j, self.sigma_at(j, pixels.centres_x[l], pixels.centres_y[l]));
            coverage.hit[l] = at.hit;
            coverage.alpha[l] = at.alpha;
            coverage.falloff[l] = at.falloff;
            coverage.saturated[l] = at.saturated;
            coverage.dx[l] = at.dx;
            coverage.dy[l] = at.dy;
        }
        coverage
    }
}

/// What front-to-back compositing leaves at each pixel of a block.
struct BlockForward {
    /// `[K]` colour sums `Σ w c`.
    colors: Vec<Lanes<f32>>,
    /// `Σ w z`.
    depth: Lanes<f32>,
    /// The depth of the footprint that first brings the transmittance to one half or below, where one did.
    median: Lanes<f32>,
    has_median: Lanes<bool>,
    transmittance: Lanes<f32>,
    /// One past the list position of the last composited footprint (0: none).
    end: Lanes<u32>,
}

/// Composites the footprints `list` (positions in the tile list, front to back) at the pixels of a block into
/// `state` (whose colour buffers are reused from block to block).
#[inline(always)]
fn composite_block(splats: &TileSplats, list: &[u32], pixels: &BlockPixels, state: &mut BlockForward) {
    let channels = state.colors.len();
    state.reset();
    let mut done = pixels.inside.map(|inside| !inside);
    let mut weights = [0.0f32; LANES];
    let mut take = [false; LANES];
    for &j in list {
        let coverage = splats.coverage(j as usize, pixels);
        state.step(&coverage, splats.depths[j as usize], j + 1, &mut done, &mut take, &mut weights);
        let color = &splats.colors[j as usize * channels..(j as usize + 1) * channels];
        for (sums, &c) in state.colors.iter_mut().zip(color) {
            accumulate(sums, c, &take, &weights);
        }
        if done.iter().all(|&d| d) {
            break;
        }
    }
}

impl BlockForward {
    fn new(channels: usize) -> Self {
        let mut state = Self {
            colors: vec![[0.0; LANES]; channels],
            depth: [0.0; LANES],
            median: [0.0; LANES],
            has_median: [false; LANES],
            transmittance: [1.0; LANES],
            end: [0; LANES],
        };
        state.reset();
        state
    }

    /// Back to nothing composited: no colour or depth, full transmittance.
    #[inline(always)]
    fn reset(&mut self) {
        self.colors.fill([0.0; LANES]);
        (self.depth, self.median, self.has_median) = ([0.0; LANES], [0.0; LANES], [false; LANES]);
        (self.transmittance, self.end) = ([1.0; LANES], [0; LANES]);
    }

    /// Composites one footprint (at `depth`, list end `end` once taken) where it is hit and the pixel goes on:
    /// marks in `take` where it does, with its weights `alpha T`, and in `done` where the pixel stops instead.
    #[inline(always)]
    fn step(
        &mut self,
        coverage: &BlockCoverage,
        depth: f32,
        end: u32,
        done: &mut Lanes<bool>,
        take: &mut Lanes<bool>,
        weights: &mut Lanes<f32>,
    ) {
        for l in 0..LANES {
            let transmittance = self.transmittance[l];
            let next = transmittance * (1.0 - coverage.alpha[l]);
            let live = coverage.hit[l] & !done[l];
            // A pixel stops without the footprint that would bring it to the transmittance floor.
            done[l] |= live & (next <= MIN_TRANSMITTANCE);
            take[l] = live & (next > MIN_TRANSMITTANCE);
            let weight = coverage.alpha[l] * transmittance;
            weights[l] = weight;
            let first_median = take[l] & !self.has_median[l] & (next <= MEDIAN_TRANSMITTANCE);
            self.median[l] = if first_median { depth } else { self.median[l] };
            self.has_median[l] |= first_median;
            self.depth[l] = if take[l] { self.depth[l] + depth * weight } else { self.depth[l] };
            self.transmittance[l] = if take[l] { next } else { transmittance };
            self.end[l] = if take[l] { end } else { self.end[l] };
        }
    }
}

/// Adds `c` times the weight to a channel's sums where the footprint is taken.
#[inline(always)]
fn accumulate(sums: &mut Lanes<f32>, c: f32, take: &Lanes<bool>, weights: &Lanes<f32>) {
    for l in 0..LANES {
        sums[l] = if take[l] { sums[l] + c * weights[l] } else { sums[l] };
    }
}

/// Composites tile row `tile_row` of the view into `out`.
pub(crate) fn composite_band(scene: &ViewScene, tile_row: usize, out: &mut BandOutput) {
    #[cfg(target_arch = "x86_64")]
    if has_wide_vectors() {
        // SAFETY: the processor supports AVX2.
        return unsafe { composite_band_avx2(scene, tile_row, out) };
    }
    composite_band_lanes(scene, tile_row, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn composite_band_avx2(scene: &ViewScene, tile_row: usize, out: &mut BandOutput) {
    composite_band_lanes(scene, tile_row, out);
}

#[inline(always)]
fn composite_band_lanes(scene: &ViewScene, tile_row: usize, out: &mut BandOutput) {
    let grid = &scene.grid;
    let channels = scene.gaussians.channels();
    let row0 = tile_row * grid.tile_size;
    let mut block = BlockForward::new(channels);
    for tile in tile_row * grid.tiles_x..(tile_row + 1) * grid.tiles_x {
        let splats = TileSplats::gather(scene, tile);
        let rect = grid.pixel_rect(tile);
        for b in 0..splats.blocks.len() {
            let (origin, list) = splats.blocks.block(b);
            let pixels = BlockPixels::new(origin, rect);
            composite_block(&splats, list, &pixels, &mut block);
            for (l, x, y) in pixels.inside() {
                write_pixel(scene, &block, l, (y - row0) * grid.width + x, out);
            }
        }
    }
}

/// Writes lane `l` of a composited block as pixel `pixel` of the band.
fn write_pixel(scene: &ViewScene, block: &BlockForward, l: usize, pixel: usize, out: &mut BandOutput) {
    let channels = block.colors.len();
    let transmittance = block.transmittance[l];
    let alpha = 1.0 - transmittance;
    let expected_depth = block.depth[l] / alpha.max(MIN_DEPTH_ALPHA);
    let colors = &mut out.colors[pixel * channels..(pixel + 1) * channels];
    for ((o, sums), bg) in colors.iter_mut().zip(&block.colors).zip(scene.background) {
        *o = sums[l] + transmittance * bg;
    }
    out.alpha[pixel] = alpha;
    out.depth[pixel] = match scene.depth {
        DepthStatistic::Expected => expected_depth,
        DepthStatistic::Median if block.has_median[l] => block.median[l],
        DepthStatistic::Median => expected_depth,
    };
    out.transmittance[pixel] = transmittance;
    out.list_ends[pixel] = block.end[l];
}

/// The state of a block's pixels while the backward pass walks their footprints back to front.
struct BlockBackward {
    /// `[K]` `dL/d colour` per pixel.
    grad_colors: Vec<Lanes<f64>>,
    /// `dL/d Σ w z` (the expected depth's numerator).
    grad_sum_depth: Lanes<f64>,
    /// `dL/d T_final`, through alpha and the background term.
    grad_final_transmittance: Lanes<f64>,
    /// The forward pass's final transmittance and list end (0 outside the image: nothing to walk).
    final_transmittance: Lanes<f64>,
    end: Lanes<u32>,
    /// The transmittance in front of the footprints walked so far.
    transmittance: Lanes<f64>,
    /// `[K]` colour, and depth, composited behind the footprints walked so far.
    colors_behind: Vec<Lanes<f64>>,
    depth_behind: Lanes<f64>,
}

impl BlockBackward {
    fn new(channels: usize) -> Self {
        Self {
            grad_colors: vec![[0.0; LANES]; channels],
            grad_sum_depth: [0.0; LANES],
            grad_final_transmittance: [0.0; LANES],
            final_transmittance: [0.0; LANES],
            end: [0; LANES],
            transmittance: [0.0; LANES],
            colors_behind: vec![[0.0; LANES]; channels],
            depth_behind: [0.0; LANES],
        }
    }

    /// Starts the walk of the block `pixels` from the forward pass's outputs and the loss gradients; adds the
    /// background's gradient `Σ dL/dc T_final` to `background`.
    fn start(
        &mut self,
        scene: &ViewScene,
        pixels: &BlockPixels,
        forward: &ForwardPixels,
        grads: &PixelGrads,
        background: &mut [f64],
    ) {
        let channels = self.grad_colors.len();
        for lanes in self.grad_colors.iter_mut().chain(&mut self.colors_behind) {
            *lanes = [0.0; LANES];
        }
        for lanes in [&mut self.grad_sum_depth, &mut self.grad_final_transmittance, &mut self.depth_behind] {
            *lanes = [0.0; LANES];
        }
        (self.final_transmittance, self.transmittance, self.end) = ([0.0; LANES], [0.0; LANES], [0; LANES]);
        for (l, x, y) in pixels.inside() {
            let pixel = y * scene.grid.width + x;
            let final_transmittance = forward.transmittance[pixel] as f64;
            let mut through_background = 0.0;
            for (k, (grad, (sum, bg))) in
                self.grad_colors.iter_mut().zip(background.iter_mut().zip(scene.background)).enumerate()
            {
                grad[l] = grads.colors.map_or(0.0, |c| c[pixel * channels + k] as f64);
                *sum += grad[l] * final_transmittance;
                through_background += grad[l] * *bg as f64;
            }
            let alpha_out = forward.alpha[pixel] as f64;
            let grad_depth_out = grads.depth.map_or(0.0, |d| d[pixel] as f64);
            // depth = D / max(alpha, eps): dD = g / max(alpha, eps); dalpha -= g depth / alpha (unless clamped).
            let clamped_alpha = alpha_out.max(MIN_DEPTH_ALPHA as f64);
            self.grad_sum_depth[l] = grad_depth_out / clamped_alpha;
            let mut grad_alpha_out = grads.alpha.map_or(0.0, |a| a[pixel] as f64);
            if alpha_out >= MIN_DEPTH_ALPHA as f64 {
                grad_alpha_out -= grad_depth_out * forward.depth[pixel] as f64 / clamped_alpha;
            }
            // Final transmittance enters through alpha = 1 - T and the background term T bg.
            self.grad_final_transmittance[l] = -grad_alpha_out + through_background;
            self.final_transmittance[l] = final_transmittance;
            self.transmittance[l] = final_transmittance;
            self.end[l] = forward.list_ends[pixel];
        }
    }

    /// Steps lane `l` back past footprint `j` (composited there, with `coverage` at lane `l`), adding the
    /// footprint's gradient at that pixel to `row`.
    #[inline(always)]
    fn step(&mut self, l: usize, j: usize, coverage: &BlockCoverage, splats: &TileSplats, row: &mut [f64]) {
        let channels = self.grad_colors.len();
        let alpha = coverage.alpha[l] as f64;
        let remaining = 1.0 - alpha;
        self.transmittance[l] /= remaining;
        let transmittance = self.transmittance[l];
        let weight = alpha * transmittance;
        let color = &splats.colors[j * channels..(j + 1) * channels];
        let mut grad_alpha = 0.0;
        for (k, &c) in color.iter().enumerate() {
            let (c, grad, behind) = (c as f64, self.grad_colors[k][l], &mut self.colors_behind[k][l]);
            row[GRAD_COLOR + k] += grad * weight;
            grad_alpha += grad * (c - *behind);
            *behind = alpha * c + remaining * *behind;
        }
        let (depth, grad_sum_depth) = (splats.depths[j] as f64, self.grad_sum_depth[l]);
        row[GRAD_DEPTH] += grad_sum_depth * weight;
        grad_alpha += grad_sum_depth * (depth - self.depth_behind[l]);
        self.depth_behind[l] = alpha * depth + remaining * self.depth_behind[l];
        grad_alpha =
            grad_alpha * transmittance - self.grad_final_transmittance[l] * self.final_transmittance[l] / remaining;
        if coverage.saturated[l] {
            return;
        }
        row[GRAD_OPACITY] += grad_alpha * coverage.falloff[l] as f64;
        // alpha = o exp(-sigma): dalpha/dsigma = -alpha.
        let grad_sigma = -grad_alpha * alpha;
        let [a, b, c] = splats.conics[j].map(f64::from);
        let (dx, dy) = (coverage.dx[l] as f64, coverage.dy[l] as f64);
        row[GRAD_CONIC] += grad_sigma * 0.5 * dx * dx;
        row[GRAD_CONIC + 1] += grad_sigma * dx * dy;
        row[GRAD_CONIC + 2] += grad_sigma * 0.5 * dy * dy;
        row[GRAD_MEAN2D] += grad_sigma * (a * dx + b * dy);
        row[GRAD_MEAN2D + 1] += grad_sigma * (b * dx + c * dy);
    }
}

/// Backward of tile `tile`: adds each listed footprint's gradient (summed over the tile's pixels) to its row
/// of `out` (`[n, grad_stride(K)]`, rows in list order), and the background gradient to `background` (`[K]`).
///
/// Block by block: a footprint's alpha at the block's pixels is evaluated in lanes as in the forward pass; the
/// `f64` gradient then runs pixel by pixel where the footprint was composited, from each pixel's list end back.
pub(crate) fn composite_tile_backward(
    scene: &ViewScene,
    tile: usize,
    forward: &ForwardPixels,
    grads: &PixelGrads,
    out: &mut [f64],
    background: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if has_wide_vectors() {
        // SAFETY: the processor supports AVX2.
        return unsafe { composite_tile_backward_avx2(scene, tile, forward, grads, out, background) };
    }
    composite_tile_backward_lanes(scene, tile, forward, grads, out, background);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn composite_tile_backward_avx2(
    scene: &ViewScene,
    tile: usize,
    forward: &ForwardPixels,
    grads: &PixelGrads,
    out: &mut [f64],
    background: &mut [f64],
) {
    composite_tile_backward_lanes(scene, tile, forward, grads, out, background);
}

#[inline(always)]
fn composite_tile_backward_lanes(
    scene: &ViewScene,
    tile: usize,
    forward: &ForwardPixels,
    grads: &PixelGrads,
    out: &mut [f64],
    background: &mut [f64],
) {
    let stride = grad_stride(scene.gaussians.channels());
    let splats = TileSplats::gather(scene, tile);
    let rect = scene.grid.pixel_rect(tile);
    let mut block = BlockBackward::new(scene.gaussians.channels());
    for b in 0..splats.blocks.len() {
        let (origin, list) = splats.blocks.block(b);
        let pixels = BlockPixels::new(origin, rect);
        block.start(scene, &pixels, forward, grads, background);
        let last_end = block.end.iter().copied().max().unwrap_or(0);
        let listed = list.partition_point(|&j| j < last_end);
        for &j in list[..listed].iter().rev() {
            let coverage = splats.coverage(j as usize, &pixels);
            let row = &mut out[j as usize * stride..(j as usize + 1) * stride];
            for l in 0..LANES {
                if coverage.hit[l] & (j < block.end[l]) {
                    block.step(l, j as usize, &coverage, &splats, row);
                }
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

    /// The coverage of footprint 0 at pixel centre `(px, py)`: `(hit, alpha, saturated)`.
    fn at(splats: &TileSplats, px: f32, py: f32) -> (bool, f32, bool) {
        let mut pixels = BlockPixels::new([0, 0], [0, 16, 0, 16]);
        pixels.centres_x[5] = px;
        pixels.centres_y[5] = py;
        let coverage = splats.coverage(0, &pixels);
        (coverage.hit[5], coverage.alpha[5], coverage.saturated[5])
    }

    #[test]
    fn coverage_follows_the_thresholds() {
        let splats = single([1.0, 0.0, 1.0], 0.5);
        assert_eq!(at(&splats, 0.0, 0.0), (true, 0.5, false));
        // sigma = 0.5 * 36 = 18: alpha far below 1/255.
        assert!(!at(&splats, 6.0, 0.0).0);
        assert_eq!(at(&single([1.0, 0.0, 1.0], 5.0), 0.0, 0.0), (true, MAX_ALPHA, true));
        // A conic that is not positive definite gives sigma < 0 away from the centre.
        assert!(!at(&single([1.0, 3.0, 1.0], 0.5), 1.0, -1.0).0);
    }

    #[test]
    fn extreme_conics_far_from_the_centre_are_skipped() {
        // a dx² and c dy² overflow to +inf, b dx dy to -inf: sigma is NaN.
        let splats = single([1e30, -1e30, 1e30], 0.9);
        assert!(!at(&splats, 1e5, 1e5).0);
        assert!(at(&splats, 0.0, 0.0).0);
    }

    /// Pixel by pixel over the whole tile list: what the block lanes must reproduce bit for bit.
    fn composite_pixel(scene: &ViewScene, splats: &TileSplats, x: usize, y: usize) -> (Vec<f32>, f32, f32, u32) {
        let channels = scene.gaussians.channels();
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        let (mut sums, mut depth, mut median, mut transmittance, mut end) =
            (vec![0.0f32; channels], 0.0f32, None, 1.0f32, 0);
        for j in 0..splats.depths.len() {
            let Some(coverage) = splats.coverage_at(j, px, py) else { continue };
            let next = transmittance * (1.0 - coverage.alpha);
            if next <= MIN_TRANSMITTANCE {
                break;
            }
            let weight = coverage.alpha * transmittance;
            for (sum, c) in sums.iter_mut().zip(&splats.colors[j * channels..]) {
                *sum += c * weight;
            }
            depth += splats.depths[j] * weight;
            if median.is_none() && next <= MEDIAN_TRANSMITTANCE {
                median = Some(splats.depths[j]);
            }
            (transmittance, end) = (next, j as u32 + 1);
        }
        let expected = depth / (1.0 - transmittance).max(MIN_DEPTH_ALPHA);
        let depth = match scene.depth {
            DepthStatistic::Expected => expected,
            DepthStatistic::Median => median.unwrap_or(expected),
        };
        let colors = sums.iter().zip(scene.background).map(|(s, bg)| s + transmittance * bg).collect();
        (colors, depth, transmittance, end)
    }

    #[test]
    fn block_lanes_composite_every_pixel_as_a_walk_over_the_tile_list_does() {
        use crate::settings::RasterSettings;
        use crate::view::{PinholeView, ViewBatch};
        let mut random = dggt_data::random::SplitMix64::new(0x9e37_79b9);
        let mut uniform = move || random.unit();
        // 37 x 23 pixels: tiles and blocks cut by both edges. Dense enough that pixels stop at the floor.
        let (width, height, count, channels) = (37u32, 23u32, 3000, 4);
        let mut buffers: [Vec<f32>; 5] = Default::default();
        for _ in 0..count {
            let depth = 2.0 + 6.0 * uniform();
            buffers[0].extend([(uniform() - 0.5) * depth * 1.2, (uniform() - 0.5) * depth * 0.8, depth]);
            buffers[1].extend([1.0, uniform() - 0.5, uniform() - 0.5, uniform() - 0.5]);
            buffers[2].extend([0.01 + 0.08 * uniform(), 0.01 + 0.08 * uniform(), 0.02]);
            buffers[3].push(0.05 + 0.95 * uniform() * 1.2);
            buffers[4].extend((0..channels).map(|_| uniform()));
        }
        let [means, quats, scales, opacities, colors] = &buffers;
        let gaussians = Gaussians::new(means, quats, scales, crate::Opacities::Shared(opacities), colors, channels)
            .expect("valid buffers");
        let size = dggt_geom::ImageSize::new(width, height).expect("non-empty");
        let camera = PinholeView {
            world_to_camera: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
            fx: 30.0,
            fy: 30.0,
            cx: 18.5,
            cy: 11.5,
        };
        let views = ViewBatch::new(vec![camera], size).expect("valid view");
        for depth in [DepthStatistic::Expected, DepthStatistic::Median] {
            let settings =
                RasterSettings { depth, background: Some(vec![0.2, 0.4, 0.6, 0.8]), ..RasterSettings::default() };
            let rendered = crate::rasterize(&gaussians, &views, &settings).expect("renders");
            let grid = TileGrid::new(width as usize, height as usize, settings.tile_size as usize);
            let background = settings.background.clone().expect("set above");
            let scene = ViewScene {
                gaussians: &gaussians,
                projection: &rendered.projection,
                bins: &rendered.bins[0],
                grid,
                view: 0,
                background: &background,
                depth,
            };
            let mut stopped = 0;
            for tile in 0..grid.len() {
                let splats = TileSplats::gather(&scene, tile);
                let [x0, x1, y0, y1] = grid.pixel_rect(tile);
                for (x, y) in (y0..y1).flat_map(|y| (x0..x1).map(move |x| (x, y))) {
                    let pixel = y * grid.width + x;
                    let (colors, depth, transmittance, end) = composite_pixel(&scene, &splats, x, y);
                    let images = &rendered.images;
                    assert_eq!(images.colors[pixel * channels..(pixel + 1) * channels], colors, "({x}, {y})");
                    assert_eq!(images.depth[pixel].to_bits(), depth.to_bits(), "({x}, {y})");
                    assert_eq!(images.alpha[pixel].to_bits(), (1.0 - transmittance).to_bits(), "({x}, {y})");
                    assert_eq!(rendered.transmittance[pixel].to_bits(), transmittance.to_bits(), "({x}, {y})");
                    assert_eq!(rendered.list_ends[pixel], end, "({x}, {y})");
                    stopped += usize::from(end < splats.depths.len() as u32 && transmittance < 0.01);
                }
            }
            assert!(stopped > 50, "only {stopped} pixels stopped early: the scene tests too little");
        }
    }

    #[test]
    fn lanes_past_the_tile_edge_are_outside() {
        let pixels = BlockPixels::new([12, 4], [0, 14, 0, 5]);
        let inside: Vec<_> = pixels.inside().map(|(_, x, y)| (x, y)).collect();
        assert_eq!(inside, [(12, 4), (13, 4)]);
    }
}
