//! Screen tiles and the per-tile, depth-sorted lists of the Gaussians that overlap them.
//!
//! Each kept Gaussian is entered in every tile its bounding box touches; each tile's list is sorted front to
//! back by camera depth (ties by Gaussian index, so the order is deterministic). Culled Gaussians never enter
//! a list and empty tiles have empty lists: compositing only visits what can contribute.

use rayon::prelude::*;

use crate::projection::Projection;

/// The tiling of one image: `tiles_x x tiles_y` squares of `tile_size` pixels, the last row and column
/// possibly cut by the image border. Tile `t` is at column `t % tiles_x`, row `t / tiles_x`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct TileGrid {
    pub tile_size: usize,
    pub tiles_x: usize,
    pub tiles_y: usize,
    pub width: usize,
    pub height: usize,
}

impl TileGrid {
    pub fn new(width: usize, height: usize, tile_size: usize) -> Self {
        Self { tile_size, tiles_x: width.div_ceil(tile_size), tiles_y: height.div_ceil(tile_size), width, height }
    }

    pub fn len(&self) -> usize {
        self.tiles_x * self.tiles_y
    }

    /// Tiles `[x0, x1) x [y0, y1)` touched by the box `mean2d ± radius`, clipped to the grid.
    pub fn tile_rect(&self, mean2d: [f32; 2], radius: [u32; 2]) -> [usize; 4] {
        let size = self.tile_size as f64;
        let range = |centre: f32, radius: u32, tiles: usize| {
            let (centre, radius) = (centre as f64, radius as f64);
            let clip = |t: f64| t.max(0.0).min(tiles as f64) as usize;
            (clip(((centre - radius) / size).floor()), clip(((centre + radius) / size).ceil()))
        };
        let (x0, x1) = range(mean2d[0], radius[0], self.tiles_x);
        let (y0, y1) = range(mean2d[1], radius[1], self.tiles_y);
        [x0, x1, y0, y1]
    }

    /// Pixels `[x0, x1) x [y0, y1)` of tile `tile`.
    pub fn pixel_rect(&self, tile: usize) -> [usize; 4] {
        let (tx, ty) = (tile % self.tiles_x, tile / self.tiles_x);
        let x0 = tx * self.tile_size;
        let y0 = ty * self.tile_size;
        [x0, (x0 + self.tile_size).min(self.width), y0, (y0 + self.tile_size).min(self.height)]
    }
}

/// The tile lists of one view: tile `t` composites Gaussians `ids[offsets[t]..offsets[t + 1]]` front to back.
///
/// `offsets` has `tiles + 1` entries; `ids` (Gaussian indices) has one entry per tile intersection.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TileBins {
    pub offsets: Vec<usize>,
    pub ids: Vec<u32>,
}

impl TileBins {
    /// Bins the kept Gaussians of view `view` (of `count`) into `grid`.
    pub(crate) fn build(grid: &TileGrid, projection: &Projection, view: usize, count: usize) -> Self {
        let kept: Vec<(u32, [usize; 4])> = (0..count)
            .filter_map(|i| {
                let footprint = projection.footprint(view * count + i)?;
                Some((i as u32, grid.tile_rect(footprint.mean2d, footprint.radius)))
            })
            .collect();
        let mut offsets = vec![0usize; grid.len() + 1];
        for_each_tile(&kept, grid, |_, tile| offsets[tile + 1] += 1);
        for t in 0..grid.len() {
            offsets[t + 1] += offsets[t];
        }
        let mut cursor = offsets.clone();
        let mut ids = vec![0u32; offsets[grid.len()]];
        // Gaussians are visited in index order, so each list starts in index order and the stable sort below
        // breaks depth ties by index.
        for_each_tile(&kept, grid, |id, tile| {
            ids[cursor[tile]] = id;
            cursor[tile] += 1;
        });
        let depths = &projection.depths[view * count..(view + 1) * count];
        split_by_offsets(&mut ids, &offsets, 1)
            .into_par_iter()
            .for_each(|list| list.sort_by(|a, b| depths[*a as usize].total_cmp(&depths[*b as usize])));
        Self { offsets, ids }
    }

    /// The Gaussians of tile `tile`, front to back.
    pub fn tile(&self, tile: usize) -> &[u32] {
        &self.ids[self.offsets[tile]..self.offsets[tile + 1]]
    }

    /// Number of tile intersections.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }
}

fn for_each_tile(kept: &[(u32, [usize; 4])], grid: &TileGrid, mut visit: impl FnMut(u32, usize)) {
    for &(id, [x0, x1, y0, y1]) in kept {
        for ty in y0..y1 {
            for tx in x0..x1 {
                visit(id, ty * grid.tiles_x + tx);
            }
        }
    }
}

/// Splits `data` into the disjoint per-tile chunks `data[offsets[t] * stride..offsets[t + 1] * stride]`.
pub(crate) fn split_by_offsets<'a, T>(mut data: &'a mut [T], offsets: &[usize], stride: usize) -> Vec<&'a mut [T]> {
    let mut chunks = Vec::with_capacity(offsets.len().saturating_sub(1));
    for window in offsets.windows(2) {
        let (chunk, rest) = data.split_at_mut((window[1] - window[0]) * stride);
        chunks.push(chunk);
        data = rest;
    }
    chunks
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_rect_covers_every_pixel_centre_in_the_box() {
        let grid = TileGrid::new(50, 40, 16);
        assert_eq!((grid.tiles_x, grid.tiles_y), (4, 3));
        let [x0, x1, y0, y1] = grid.tile_rect([20.3, 5.0], [5, 3]);
        assert_eq!([x0, x1, y0, y1], [0, 2, 0, 1]);
        // Box far outside on the left: empty range.
        let [x0, x1, ..] = grid.tile_rect([-100.0, 5.0], [5, 3]);
        assert_eq!(x0, x1);
        // Huge box: clipped to the grid.
        assert_eq!(grid.tile_rect([0.0, 0.0], [u32::MAX, u32::MAX]), [0, 4, 0, 3]);
        assert_eq!(grid.pixel_rect(11), [48, 50, 32, 40]);
    }
}
