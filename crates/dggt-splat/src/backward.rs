//! The backward pass: loss gradients of the images to gradients of every Gaussian input and the background.
//!
//! Per view: each tile walks its pixels back to front and sums per-footprint gradients (in parallel over
//! tiles, one gradient row per tile-list entry); each Gaussian's rows are then added in list order and its
//! footprint gradient is pulled back through the projection (in parallel over Gaussians). All sums
//! run in `f64` in a fixed order, so the result is bit-identical for any number of threads.

use rayon::prelude::*;

use crate::composite::{
    ForwardPixels, GRAD_COLOR, GRAD_CONIC, GRAD_DEPTH, GRAD_MEAN2D, GRAD_OPACITY, PixelGrads, ViewScene,
    composite_tile_backward, grad_stride,
};
use crate::error::{SplatError, expect_len};
use crate::forward::Rasterized;
use crate::gaussians::{Gaussians, Opacities};
use crate::projection::{FootprintGrad, GeometryGrad, project_backward};
use crate::settings::{DepthStatistic, RasterSettings};
use crate::tiles::split_by_offsets;
use crate::view::ViewBatch;

/// Loss gradients of the rendered images, shaped like [`Images`](crate::Images); `None` means zero.
#[derive(Debug, Clone, Copy, Default)]
pub struct ImageGrads<'a> {
    /// `[V, H, W, K]`.
    pub colors: Option<&'a [f32]>,
    /// `[V, H, W]`.
    pub alpha: Option<&'a [f32]>,
    /// `[V, H, W]` (of the expected depth: a render of the median depth takes none).
    pub depth: Option<&'a [f32]>,
}

/// Loss gradients of the inputs.
///
/// | buffer | shape |
/// |---|---|
/// | `means` | `[N, 3]` |
/// | `quats` | `[N, 4]`, w.r.t. the unnormalised input quaternions (`w x y z`) |
/// | `scales` | `[N, 3]` |
/// | `opacities` | `Shared([N])` or `PerView([V, N])`, as the input |
/// | `colors` | `[N, K]` |
/// | `background` | `[K]` |
///
/// Culled Gaussians get zero gradients from the views that culled them. Values are computed in `f64` and
/// saturate at `±f32::MAX` when converted.
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianGrads {
    pub means: Vec<f32>,
    pub quats: Vec<f32>,
    pub scales: Vec<f32>,
    pub opacities: Opacities<Vec<f32>>,
    pub colors: Vec<f32>,
    pub background: Vec<f32>,
}

/// Gradients of the inputs of [`rasterize`](crate::rasterize) given gradients of its images.
///
/// `gaussians`, `views` and `settings` must be those the forward pass ran with (sizes are checked, values are
/// not). Non-finite image gradients are an error, and so is a depth gradient of a median-depth render (the median
/// depth is a constant of the render).
pub fn rasterize_backward(
    gaussians: &Gaussians,
    views: &ViewBatch,
    settings: &RasterSettings,
    forward: &Rasterized,
    grads: &ImageGrads,
) -> Result<GaussianGrads, SplatError> {
    let layout = forward.layout;
    layout.check(gaussians, views, settings)?;
    let (count, channels, pixels) = (layout.gaussians, layout.channels, layout.pixels());
    check_image_grad("grad colors", grads.colors, layout.views * pixels, channels, "[V, H, W, K]")?;
    check_image_grad("grad alpha", grads.alpha, layout.views * pixels, 1, "[V, H, W]")?;
    check_image_grad("grad depth", grads.depth, layout.views * pixels, 1, "[V, H, W]")?;
    if settings.depth == DepthStatistic::Median && grads.depth.is_some() {
        return Err(SplatError::InvalidSettings {
            detail: "the median depth carries no gradient: render the expected depth to train on depth".into(),
        });
    }

    let grid = layout.grid();
    let background = settings.background_or_black(channels);
    let stride = grad_stride(channels);
    let mut geometry = vec![GeometryGrad::default(); count];
    let mut colors = vec![0.0f64; count * channels];
    let mut opacities = vec![0.0f64; if layout.per_view_opacities { layout.views * count } else { count }];
    let mut background_grad = vec![0.0f64; channels];

    for v in 0..layout.views {
        let bins = &forward.bins[v];
        let scene = ViewScene {
            gaussians,
            projection: &forward.projection,
            bins,
            grid,
            view: v,
            background: &background,
            depth: settings.depth,
        };
        let pixel_range = v * pixels..(v + 1) * pixels;
        let view_pixels = ForwardPixels {
            alpha: &forward.images.alpha[pixel_range.clone()],
            depth: &forward.images.depth[pixel_range.clone()],
            transmittance: &forward.transmittance[pixel_range.clone()],
            list_ends: &forward.list_ends[pixel_range.clone()],
        };
        let view_grads = PixelGrads {
            colors: grads.colors.map(|c| &c[v * pixels * channels..(v + 1) * pixels * channels]),
            alpha: grads.alpha.map(|a| &a[pixel_range.clone()]),
            depth: grads.depth.map(|d| &d[pixel_range.clone()]),
        };

        let mut rows = vec![0.0f64; bins.len() * stride];
        let mut tile_background = vec![0.0f64; grid.len() * channels];
        split_by_offsets(&mut rows, &bins.offsets, stride)
            .into_par_iter()
            .zip(tile_background.par_chunks_mut(channels))
            .enumerate()
            .for_each(|(tile, (out, bg))| composite_tile_backward(&scene, tile, &view_pixels, &view_grads, out, bg));
        for tile in tile_background.chunks(channels) {
            for (sum, g) in background_grad.iter_mut().zip(tile) {
                *sum += g;
            }
        }

        let entries = EntriesByGaussian::new(&bins.ids, count);
        let view_opacities =
            if layout.per_view_opacities { &mut opacities[v * count..(v + 1) * count] } else { &mut opacities[..] };
        let culled = &forward.projection.culled[v * count..(v + 1) * count];
        let camera = &views.views()[v];
        geometry
            .par_iter_mut()
            .zip(colors.par_chunks_mut(channels))
            .zip(view_opacities.par_iter_mut())
            .enumerate()
            .for_each_init(
                || vec![0.0f64; stride],
                |row, (i, ((geometry, color), opacity))| {
                    if culled[i].is_some() {
                        return;
                    }
                    entries.sum_rows(i, &rows, row);
                    *opacity += row[GRAD_OPACITY];
                    for (c, g) in color.iter_mut().zip(&row[GRAD_COLOR..]) {
                        *c += g;
                    }
                    let footprint = FootprintGrad {
                        mean2d: [row[GRAD_MEAN2D], row[GRAD_MEAN2D + 1]],
                        conic: [row[GRAD_CONIC], row[GRAD_CONIC + 1], row[GRAD_CONIC + 2]],
                        depth: row[GRAD_DEPTH],
                    };
                    let g = project_backward(gaussians, i, camera, views, settings, &footprint);
                    add(&mut geometry.mean, &g.mean);
                    add(&mut geometry.quat, &g.quat);
                    add(&mut geometry.scale, &g.scale);
                },
            );
    }

    let opacities = to_f32(&opacities);
    Ok(GaussianGrads {
        means: to_f32(geometry.iter().flat_map(|g| g.mean).collect::<Vec<_>>().as_slice()),
        quats: to_f32(geometry.iter().flat_map(|g| g.quat).collect::<Vec<_>>().as_slice()),
        scales: to_f32(geometry.iter().flat_map(|g| g.scale).collect::<Vec<_>>().as_slice()),
        opacities: if layout.per_view_opacities { Opacities::PerView(opacities) } else { Opacities::Shared(opacities) },
        colors: to_f32(&colors),
        background: to_f32(&background_grad),
    })
}

/// The tile-list entries of each Gaussian of one view, in list order: its gradient rows are summed in the order
/// a pass over the whole list would add them, so the sums do not depend on how the Gaussians are split across
/// threads.
struct EntriesByGaussian {
    /// `[N + 1]`: Gaussian `i`'s entries are `entries[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<u32>,
    entries: Vec<u32>,
}

impl EntriesByGaussian {
    /// Groups the entries of `ids` (the Gaussian of each tile-list entry) by Gaussian, of `count`.
    fn new(ids: &[u32], count: usize) -> Self {
        let mut offsets = vec![0u32; count + 1];
        for &id in ids {
            offsets[id as usize + 1] += 1;
        }
        for i in 0..count {
            offsets[i + 1] += offsets[i];
        }
        let mut cursor = offsets.clone();
        let mut entries = vec![0u32; ids.len()];
        for (entry, &id) in ids.iter().enumerate() {
            entries[cursor[id as usize] as usize] = entry as u32;
            cursor[id as usize] += 1;
        }
        Self { offsets, entries }
    }

    /// Writes into `sum` the sum of Gaussian `i`'s rows of `rows` (`sum.len()` values each, one per entry), in
    /// list order.
    fn sum_rows(&self, i: usize, rows: &[f64], sum: &mut [f64]) {
        let stride = sum.len();
        sum.fill(0.0);
        for &entry in &self.entries[self.offsets[i] as usize..self.offsets[i + 1] as usize] {
            let row = &rows[entry as usize * stride..(entry as usize + 1) * stride];
            for (s, r) in sum.iter_mut().zip(row) {
                *s += r;
            }
        }
    }
}

fn check_image_grad(
    what: &'static str,
    values: Option<&[f32]>,
    pixels: usize,
    channels: usize,
    shape: &str,
) -> Result<(), SplatError> {
    let Some(values) = values else { return Ok(()) };
    expect_len(what, values, pixels, channels, shape)?;
    if values.iter().any(|v| !v.is_finite()) {
        return Err(SplatError::NonFinite { what });
    }
    Ok(())
}

fn add<const L: usize>(sum: &mut [f64; L], value: &[f64; L]) {
    for (s, v) in sum.iter_mut().zip(value) {
        *s += v;
    }
}

/// `f64` to `f32`, saturating at `±f32::MAX` instead of overflowing to infinity.
fn to_f32(values: &[f64]) -> Vec<f32> {
    values.iter().map(|v| v.clamp(-(f32::MAX as f64), f32::MAX as f64) as f32).collect()
}
