//! The forward pass over a batch of views: project, cull, bin into tiles, composite; and what it keeps for the
//! backward pass.

use rayon::prelude::*;

use crate::composite::{BandOutput, ViewScene, composite_band};
use crate::cull::CullStats;
use crate::error::SplatError;
use crate::gaussians::{Gaussians, Opacities};
use crate::projection::Projection;
use crate::settings::RasterSettings;
use crate::tiles::{TileBins, TileGrid, split_by_offsets};
use crate::view::ViewBatch;

/// The rendered images of a batch.
///
/// | buffer | shape | meaning |
/// |---|---|---|
/// | `colors` | `[V, H, W, K]` | composited colours plus `T_final · background` |
/// | `alpha` | `[V, H, W]` | `1 - T_final` |
/// | `depth` | `[V, H, W]` | expected depth `Σ w z / max(alpha, 1e-10)`, or the median depth (see [`DepthStatistic`](crate::DepthStatistic)); camera-space z, 0 where nothing is drawn |
#[derive(Debug, Clone, PartialEq)]
pub struct Images {
    pub colors: Vec<f32>,
    pub alpha: Vec<f32>,
    pub depth: Vec<f32>,
}

/// Everything the forward pass produced: the images, per-view culling statistics, and the state the backward
/// pass reads (projection, tile lists, per-pixel stopping points).
#[derive(Debug, Clone, PartialEq)]
pub struct Rasterized {
    pub images: Images,
    /// `[V]`.
    pub stats: Vec<CullStats>,
    pub projection: Projection,
    /// `[V]` depth-sorted tile lists.
    pub bins: Vec<TileBins>,
    /// `[V, H, W]` transmittance after the last composited footprint.
    pub transmittance: Vec<f32>,
    /// `[V, H, W]` position in the pixel's tile list one past the last composited footprint (0: none).
    pub list_ends: Vec<u32>,
    pub(crate) layout: BatchLayout,
}

/// The sizes a forward result was computed for; the backward checks its inputs against them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct BatchLayout {
    pub views: usize,
    pub gaussians: usize,
    pub channels: usize,
    pub width: usize,
    pub height: usize,
    pub tile_size: usize,
    pub per_view_opacities: bool,
}

impl BatchLayout {
    fn of(gaussians: &Gaussians, views: &ViewBatch, settings: &RasterSettings) -> Self {
        Self {
            views: views.len(),
            gaussians: gaussians.len(),
            channels: gaussians.channels(),
            width: views.width(),
            height: views.height(),
            tile_size: settings.tile_size as usize,
            per_view_opacities: matches!(gaussians.opacities(), Opacities::PerView(_)),
        }
    }

    pub(crate) fn pixels(&self) -> usize {
        self.width * self.height
    }

    pub(crate) fn grid(&self) -> TileGrid {
        TileGrid::new(self.width, self.height, self.tile_size)
    }

    /// Checks that a forward result with this layout belongs to these inputs.
    pub(crate) fn check(
        &self,
        gaussians: &Gaussians,
        views: &ViewBatch,
        settings: &RasterSettings,
    ) -> Result<(), SplatError> {
        let actual = Self::of(gaussians, views, settings);
        if actual != *self {
            return Err(SplatError::ForwardMismatch {
                detail: format!("forward pass ran for {self:?}, backward called with {actual:?}"),
            });
        }
        Ok(())
    }
}

/// Renders `gaussians` into every view of `views`.
///
/// Per-Gaussian problems never fail the call (see [`CullReason`](crate::CullReason)); buffer shapes,
/// cameras and settings are checked and reported as [`SplatError`]. The result is bit-identical for any
/// number of threads.
pub fn rasterize(
    gaussians: &Gaussians,
    views: &ViewBatch,
    settings: &RasterSettings,
) -> Result<Rasterized, SplatError> {
    settings.validate(gaussians.channels())?;
    gaussians.check_views(views.len())?;
    let layout = BatchLayout::of(gaussians, views, settings);
    let grid = layout.grid();
    let (count, channels, width) = (layout.gaussians, layout.channels, layout.width);
    let background = settings.background_or_black(channels);

    let projection = Projection::compute(gaussians, views, settings);
    let bins: Vec<TileBins> =
        (0..layout.views).into_par_iter().map(|v| TileBins::build(&grid, &projection, v, count)).collect();
    let stats: Vec<CullStats> = bins
        .iter()
        .enumerate()
        .map(|(v, b)| CullStats::count(&projection.culled[v * count..(v + 1) * count], b.len()))
        .collect();
    for (v, s) in stats.iter().enumerate() {
        tracing::debug!(view = v, kept = s.kept, tile_intersections = s.tile_intersections, "rasterised: {s}");
    }

    let pixels = layout.views * layout.pixels();
    let mut images =
        Images { colors: vec![0.0; pixels * channels], alpha: vec![0.0; pixels], depth: vec![0.0; pixels] };
    let mut transmittance = vec![0.0f32; pixels];
    let mut list_ends = vec![0u32; pixels];

    // Bands of one tile row each, over all views: row offsets v * H + min(ty * tile, H).
    let band_rows: Vec<usize> =
        std::iter::once(0)
            .chain((0..layout.views).flat_map(|v| {
                (1..=grid.tiles_y).map(move |ty| v * grid.height + (ty * grid.tile_size).min(grid.height))
            }))
            .collect();
    let colors = split_by_offsets(&mut images.colors, &band_rows, width * channels);
    let alpha = split_by_offsets(&mut images.alpha, &band_rows, width);
    let depth = split_by_offsets(&mut images.depth, &band_rows, width);
    let transmittances = split_by_offsets(&mut transmittance, &band_rows, width);
    let ends = split_by_offsets(&mut list_ends, &band_rows, width);
    let scenes: Vec<ViewScene> = (0..layout.views)
        .map(|v| ViewScene {
            gaussians,
            projection: &projection,
            bins: &bins[v],
            grid,
            view: v,
            background: &background,
            depth: settings.depth,
        })
        .collect();
    (colors, alpha, depth, transmittances, ends).into_par_iter().enumerate().for_each(
        |(band, (colors, alpha, depth, transmittance, list_ends))| {
            let (v, tile_row) = (band / grid.tiles_y, band % grid.tiles_y);
            composite_band(&scenes[v], tile_row, &mut BandOutput { colors, alpha, depth, transmittance, list_ends });
        },
    );

    Ok(Rasterized { images, stats, projection, bins, transmittance, list_ends, layout })
}
