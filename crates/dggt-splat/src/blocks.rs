//! Which footprints of a tile can reach each small block of its pixels, and the falloff beyond which a
//! footprint is skipped — so compositing never evaluates a pair it would skip anyway.
//!
//! A footprint contributes to a pixel only where `alpha = o exp(-sigma) >= 1/255`, that is where
//! `sigma <= ln(255 o)`: inside an ellipse of the conic. Each tile is cut into `BLOCK x BLOCK` pixel blocks
//! and a footprint is listed in a block only if that ellipse's bounding box reaches one of the block's pixel
//! centres. The lists keep the tile's depth order, so compositing a block's list gives exactly the result of
//! compositing the whole tile list: the bounds are widened to cover the rounding of the `f32` evaluation, and
//! conics too ill-conditioned to bound safely are listed in every block.

/// Side of a block in pixels.
pub(crate) const BLOCK: usize = 4;

/// Relative rounding of the `f32` sigma evaluation that the bounds allow for (a few ulps, with a wide margin).
const SIGMA_ROUNDING: f64 = 1e-5;
/// Absolute slack on the falloff cutoff, covering the rounding of `exp` and of the alpha threshold test.
const CUTOFF_SLACK: f64 = 1e-4;
/// Conics whose eigenvalue ratio exceeds this are listed in every block rather than bounded.
const MAX_CONDITION: f64 = 1e4;
/// Slack in pixels on a bounding box, covering the rounding of `mean2d - centre`.
const BOX_SLACK: f64 = 1e-2;

/// A footprint's reach: skip it where `sigma > cutoff`; `None` half-extents mean "every block". The
/// half-extents are rounded up to `f32` (16 bytes a footprint: one is kept per view and Gaussian).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Reach {
    pub cutoff: f32,
    pub half_extent: Option<[f32; 2]>,
}

impl Reach {
    /// The reach of a culled footprint: none.
    pub const NOWHERE: Self = Self { cutoff: f32::NEG_INFINITY, half_extent: Some([-1.0, -1.0]) };

    /// The reach of a footprint with conic `[a, b, c]` and opacity `opacity` at alpha threshold `threshold`.
    pub fn new(conic: [f32; 3], opacity: f32, threshold: f32) -> Self {
        let [a, b, c] = conic.map(f64::from);
        let opacity = f64::from(opacity);
        let log_cutoff = (opacity / f64::from(threshold)).ln();
        if !log_cutoff.is_finite() || ![a, b, c].iter().all(|v| v.is_finite()) {
            // NaN or infinite inputs: evaluate everywhere and let the exact test decide.
            return Self { cutoff: f32::INFINITY, half_extent: None };
        }
        // The exact test compares the f32 sigma it computed, so this cutoff only needs the rounding of exp.
        let cutoff = (log_cutoff + CUTOFF_SLACK) as f32;
        let half_trace = 0.5 * (a + c);
        let spread = (0.25 * (a - c) * (a - c) + b * b).sqrt();
        let (lambda_min, lambda_abs) = (half_trace - spread, a.abs() + c.abs() + 2.0 * b.abs());
        if lambda_min <= 0.0 || lambda_abs > MAX_CONDITION * lambda_min {
            return Self { cutoff, half_extent: None };
        }
        // The box bounds the exact sigma: where the f32 sigma is at most s, the exact one is at most
        // s (1 + rounding · condition).
        let bound = (log_cutoff + CUTOFF_SLACK) * (1.0 + SIGMA_ROUNDING * lambda_abs / lambda_min);
        let half_extent = if bound < 0.0 {
            // Never reaches 1/255 anywhere (sigma >= 0 wherever it is not skipped).
            [-1.0, -1.0]
        } else {
            // ½ dᵀ C d <= s  ⇒  |dx| <= sqrt(2 s (C⁻¹)xx), |dy| <= sqrt(2 s (C⁻¹)yy).
            let det = a * c - b * b;
            [(2.0 * bound * c / det).sqrt() + BOX_SLACK, (2.0 * bound * a / det).sqrt() + BOX_SLACK]
        };
        Self { cutoff, half_extent: Some(half_extent.map(f32_at_least)) }
    }
}

/// The smallest `f32` at least `x` (a half-extent only ever widens when stored).
fn f32_at_least(x: f64) -> f32 {
    let rounded = x as f32;
    if f64::from(rounded) < x { rounded.next_up() } else { rounded }
}

/// Per block of one tile, the positions in the tile list of the footprints that can reach it, in list order.
pub(crate) struct BlockLists {
    blocks_x: usize,
    origin: [usize; 2],
    offsets: Vec<u32>,
    entries: Vec<u32>,
}

impl BlockLists {
    /// Lists for the tile with pixels `[x0, x1) x [y0, y1)` of footprints at `means2d` with `reaches`.
    pub fn build(rect: [usize; 4], means2d: &[[f32; 2]], reaches: &[Reach]) -> Self {
        let [x0, x1, y0, y1] = rect;
        let blocks_x = (x1 - x0).div_ceil(BLOCK);
        let blocks_y = (y1 - y0).div_ceil(BLOCK);
        let blocks = blocks_x * blocks_y;
        // Pixel-centre span of block column `bx` (or row): [start + 0.5, end - 0.5].
        let centre_span = |origin: usize, end: usize, index: usize| {
            let start = origin + index * BLOCK;
            (start as f64 + 0.5, ((start + BLOCK).min(end)) as f64 - 0.5)
        };
        let block_range = |centre: f64, half: f64, origin: usize, end: usize, count: usize| {
            let first = (0..count).find(|&i| centre_span(origin, end, i).1 >= centre - half);
            let last = (0..count).rev().find(|&i| centre_span(origin, end, i).0 <= centre + half);
            match (first, last) {
                (Some(first), Some(last)) if first <= last => first..last + 1,
                _ => 0..0,
            }
        };
        let spans: Vec<[std::ops::Range<usize>; 2]> = means2d
            .iter()
            .zip(reaches)
            .map(|(mean, reach)| match reach.half_extent {
                None => [0..blocks_x, 0..blocks_y],
                Some([hx, hy]) if hx < 0.0 || hy < 0.0 => [0..0, 0..0],
                Some([hx, hy]) => [
                    block_range(f64::from(mean[0]), f64::from(hx), x0, x1, blocks_x),
                    block_range(f64::from(mean[1]), f64::from(hy), y0, y1, blocks_y),
                ],
            })
            .collect();
        let mut counts = vec![0u32; blocks + 1];
        for [xs, ys] in &spans {
            for by in ys.clone() {
                for bx in xs.clone() {
                    counts[by * blocks_x + bx + 1] += 1;
                }
            }
        }
        for b in 0..blocks {
            counts[b + 1] += counts[b];
        }
        let offsets = counts;
        let mut cursor = offsets.clone();
        let mut entries = vec![0u32; offsets[blocks] as usize];
        for (j, [xs, ys]) in spans.iter().enumerate() {
            for by in ys.clone() {
                for bx in xs.clone() {
                    let block = by * blocks_x + bx;
                    entries[cursor[block] as usize] = j as u32;
                    cursor[block] += 1;
                }
            }
        }
        Self { blocks_x, origin: [x0, y0], offsets, entries }
    }

    /// Number of blocks.
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Block `b`'s top-left pixel and the list positions that can reach its pixels, in list order.
    pub fn block(&self, b: usize) -> ([usize; 2], &[u32]) {
        let origin = [self.origin[0] + (b % self.blocks_x) * BLOCK, self.origin[1] + (b / self.blocks_x) * BLOCK];
        (origin, &self.entries[self.offsets[b] as usize..self.offsets[b + 1] as usize])
    }

    /// The list positions that can reach pixel `(x, y)` of the tile, in list order.
    #[cfg(test)]
    pub fn at(&self, x: usize, y: usize) -> &[u32] {
        let block = ((y - self.origin[1]) / BLOCK) * self.blocks_x + (x - self.origin[0]) / BLOCK;
        &self.entries[self.offsets[block] as usize..self.offsets[block + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::constants::{ALPHA_THRESHOLD, MAX_ALPHA};

    /// Exact skip rule of the compositor, evaluated in f32 as it does.
    fn reaches_pixel(mean: [f32; 2], conic: [f32; 3], opacity: f32, px: f32, py: f32) -> bool {
        let (dx, dy) = (mean[0] - px, mean[1] - py);
        let sigma = 0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) + conic[1] * dx * dy;
        let alpha = (opacity * (-sigma).exp()).min(MAX_ALPHA);
        sigma >= 0.0 && alpha >= ALPHA_THRESHOLD
    }

    #[test]
    fn every_reached_pixel_is_in_a_listed_block() {
        let mut state = 0x1234_5678_u64;
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) as f32
        };
        let rect = [16, 32, 0, 13];
        let mut listed_pairs = 0;
        let mut reached_pairs = 0;
        for _ in 0..2000 {
            let mean = [8.0 + 32.0 * uniform(), -8.0 + 30.0 * uniform()];
            let scale = 0.05 + 5.0 * uniform();
            let (sx, sy, rho) = (scale * (0.2 + uniform()), scale * (0.2 + uniform()), 1.9 * uniform() - 0.95);
            let (xx, yy, xy) = (sx * sx, sy * sy, rho * sx * sy);
            let det = xx * yy - xy * xy;
            let conic = [yy / det, -xy / det, xx / det];
            let opacity = uniform();
            let reach = Reach::new(conic, opacity, ALPHA_THRESHOLD);
            let lists = BlockLists::build(rect, &[mean], &[reach]);
            for y in rect[2]..rect[3] {
                for x in rect[0]..rect[1] {
                    let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                    let listed = !lists.at(x, y).is_empty();
                    let reached = reaches_pixel(mean, conic, opacity, px, py);
                    assert!(
                        listed || !reached,
                        "pixel ({x}, {y}) reached by {mean:?} {conic:?} {opacity} but not listed"
                    );
                    if reached {
                        // Inside the cutoff wherever the compositor would use the footprint.
                        let (dx, dy) = (mean[0] - px, mean[1] - py);
                        let sigma = 0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) + conic[1] * dx * dy;
                        assert!(sigma <= reach.cutoff);
                    }
                    listed_pairs += listed as usize;
                    reached_pairs += reached as usize;
                }
            }
        }
        // The bound is useful: far fewer pixel pairs listed than the whole tile.
        assert!(reached_pairs > 0);
        assert!(listed_pairs < 2000 * 16 * 13 / 3, "{listed_pairs} listed pairs");
    }

    #[test]
    fn degenerate_conics_are_listed_everywhere() {
        let rect = [0, 16, 0, 16];
        for conic in [[1.0, 2.0, 1.0], [f32::NAN, 0.0, 1.0], [1e8, 0.0, 1e-4]] {
            let reach = Reach::new(conic, 0.5, ALPHA_THRESHOLD);
            assert_eq!(reach.half_extent, None, "{conic:?}");
            let lists = BlockLists::build(rect, &[[100.0, 100.0]], &[reach]);
            assert_eq!(lists.at(0, 0), &[0]);
            assert_eq!(lists.at(15, 15), &[0]);
        }
        // An opacity below the threshold reaches nothing.
        let faint = Reach::new([1.0, 0.0, 1.0], 0.001, ALPHA_THRESHOLD);
        assert!(BlockLists::build(rect, &[[8.0, 8.0]], &[faint]).at(8, 8).is_empty());
    }
}
