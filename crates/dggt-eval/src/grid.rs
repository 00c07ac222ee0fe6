//! Where the quarter-resolution depth cells of a view (`depth_flows_4`, or the lidar binned the same way) fall in the rendered view.
//!
//! Cell `(row, col)` of a map belongs to the full-resolution pixels `4 row .. 4 row + 4` x `4 col .. 4 col + 4`
//! and is sampled at its centre, continuous coordinates `(4 col + 2, 4 row + 2)` of the original image. The
//! network sees the image resized by `(sx, sy) = (resized / original)` per axis and cropped by `crop_top`
//! rows, so that point lies at `(x sx, y sy - crop_top)` in the rendered view. A rendered map is read there as
//! [`CellSampling`] says: by default bilinearly between pixel centres ([`dggt_metrics::sample_bilinear`]), or
//! the rendered pixel the point falls on, the pixel the training's depth terms compare with the same cell
//! (`dggt_objective::depth_flow_samples`). A cell takes part when its lidar depth is
//! positive, none of its 16 full-resolution pixels is sky in the export's sky mask (mask value at least 128,
//! the binarisation the preprocessing uses), and its centre lies inside the cropped view.

use dggt_data::PreprocessPlan;
use dggt_data::depth_flow::DEPTH_FLOW_STRIDE;

use dggt_metrics::{sample_bilinear, sample_pixel};

/// How a rendered map (depth, its span, flow) is read at a lidar cell's centre.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CellSampling {
    /// Bilinear between the four nearest pixel centres: at a depth edge this blends the near surface with the
    /// far one, a depth neither holds.
    #[default]
    Bilinear,
    /// The rendered pixel the centre falls on: a point on a depth edge reads one surface or the other.
    Pixel,
}

impl CellSampling {
    /// How the report's depth protocol says it.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Pixel => "at the rendered pixel it falls on",
            Self::Bilinear => "bilinearly between pixel centres",
        }
    }
}

/// The map from original-image coordinates to network-image coordinates of one preprocessing plan, and how a
/// rendered map is read there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellMapping {
    pub scale_x: f64,
    pub scale_y: f64,
    pub crop_top: f64,
    /// The network image size.
    pub width: usize,
    pub height: usize,
    pub sampling: CellSampling,
}

impl CellMapping {
    pub fn new(plan: &PreprocessPlan, sampling: CellSampling) -> Self {
        Self {
            scale_x: f64::from(plan.resized.width) / f64::from(plan.original.width),
            scale_y: f64::from(plan.resized.height) / f64::from(plan.original.height),
            crop_top: f64::from(plan.crop_top),
            width: plan.output.width as usize,
            height: plan.output.height as usize,
            sampling,
        }
    }

    /// Network-image coordinates of the centre of cell `(row, col)`.
    pub fn cell_centre(&self, row: usize, col: usize) -> (f64, f64) {
        let stride = f64::from(DEPTH_FLOW_STRIDE);
        let (x, y) = (stride * col as f64 + stride / 2.0, stride * row as f64 + stride / 2.0);
        (x * self.scale_x, y * self.scale_y - self.crop_top)
    }

    /// The rendered map (`width x height`, row-major) at the centre of cell `(row, col)`, read as
    /// [`Self::sampling`] says; `None` outside.
    pub fn sample(&self, map: &[f32], row: usize, col: usize) -> Option<f32> {
        let (x, y) = self.cell_centre(row, col);
        match self.sampling {
            CellSampling::Pixel => sample_pixel(map, self.width, self.height, x, y),
            CellSampling::Bilinear => sample_bilinear(map, self.width, self.height, x, y),
        }
    }
}

/// Whether any full-resolution pixel of cell `(row, col)` is sky in a row-major 8-bit mask of
/// `width x height` (value at least 128). Pixels beyond the mask (a cell cut by the integer division of the
/// map size) are not looked at.
pub fn cell_has_sky(mask: &[u8], width: usize, height: usize, row: usize, col: usize) -> bool {
    let stride = DEPTH_FLOW_STRIDE as usize;
    (stride * row..(stride * row + stride).min(height))
        .any(|r| (stride * col..(stride * col + stride).min(width)).any(|c| mask[r * width + c] >= 128))
}

/// A lidar cell lies at a depth edge when the rendered expected depth's 3x3 neighbourhood around it spans more
/// than this factor (largest over smallest): there the render blends a near and a far surface.
pub const DEPTH_EDGE_SPAN: f32 = 1.3;

/// Per pixel, the largest over the smallest expected depth of its 3x3 neighbourhood (clamped at the border);
/// an empty pixel (depth 0) beside a drawn one spans without bound.
pub fn depth_span(depth: &[f32], width: usize, height: usize) -> Vec<f32> {
    let mut span = Vec::with_capacity(depth.len());
    for y in 0..height {
        for x in 0..width {
            let (mut low, mut high) = (f32::INFINITY, 0.0f32);
            for ny in y.saturating_sub(1)..(y + 2).min(height) {
                for nx in x.saturating_sub(1)..(x + 2).min(width) {
                    let d = depth[ny * width + nx];
                    (low, high) = (low.min(d), high.max(d));
                }
            }
            span.push(high / low.max(1e-6));
        }
    }
    span
}

#[cfg(test)]
mod tests {
    use super::{DEPTH_EDGE_SPAN, depth_span};

    #[test]
    fn a_depth_step_spans_its_ratio_on_both_sides_and_nothing_away_from_it() {
        // 5 x 3: depth 4 in columns 0-1, 10 in columns 2-4.
        let depth: Vec<f32> = (0..15).map(|i| if i % 5 < 2 { 4.0 } else { 10.0 }).collect();
        let span = depth_span(&depth, 5, 3);
        for row in 0..3 {
            let at = |col: usize| span[row * 5 + col];
            assert_eq!(at(0), 1.0, "column 0 sees only the near surface");
            assert_eq!((at(1), at(2)), (2.5, 2.5), "both sides of the step span 10 / 4");
            assert_eq!((at(3), at(4)), (1.0, 1.0), "columns 3-4 see only the far surface");
        }
        assert!(at_edge(2.5) && !at_edge(1.0), "a 2.5x step is an edge, a flat surface is not");
    }

    #[test]
    fn an_empty_pixel_beside_a_drawn_one_is_an_edge() {
        let span = depth_span(&[0.0, 5.0, 5.0], 3, 1);
        assert!(span[0] > 1e6 && span[1] > 1e6, "empty beside drawn: {span:?}");
        assert_eq!(span[2], 1.0, "the far end sees only the surface");
    }

    fn at_edge(span: f32) -> bool {
        span > DEPTH_EDGE_SPAN
    }
}
