//! The dynamic pixels of one input view grouped into objects: connected components of the pixel grid whose
//! neighbours lie on one surface.
//!
//! Why not a metric clustering (the release's DBSCAN over 3D points): the Gaussians are pixel-aligned, so each
//! point's neighbours are the pixels beside it, found in constant time without a spatial index; and a
//! reconstruction's units are whatever scale the network predicted, so a radius in world units has no meaning
//! from one scene to the next. Two 4-neighbours join when both are dynamic and their distances from the camera
//! differ by at most [`ClusterSettings::depth_jump`] pixel footprints (the width a pixel covers at the nearer
//! one's distance, `distance x pixel angle`): a depth edge (a car in front of another, a car against the road
//! behind it) separates, a continuous surface does not, at any scale and any resolution, up to the slant the
//! threshold allows (8 footprints: a surface turned up to 83 degrees from facing the camera). Components smaller
//! than [`ClusterSettings::min_pixels`] are dropped as mask noise. An object split in one view by an occluder,
//! or seen by several cameras at once, is joined afterwards ([`crate::link`]).

use dggt_geom::glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::union_find::UnionFind;

/// The host data of one input view that clustering reads: its pixels' Gaussian means and dynamic
/// probabilities, row-major, in the reconstruction's world.
#[derive(Debug, Clone, Copy)]
pub struct ViewPoints<'a> {
    /// Position of the camera in the rig.
    pub rig_camera: usize,
    /// Scene time of the view.
    pub time: f64,
    pub width: usize,
    pub height: usize,
    /// World position of the camera centre.
    pub camera_centre: DVec3,
    /// Angle one pixel spans (radians; `1 / focal length in pixels`).
    pub pixel_angle: f64,
    /// `[H · W]` Gaussian means.
    pub points: &'a [[f32; 3]],
    /// `[H · W]` probability that the pixel is dynamic (`sigmoid` of the dynamic logit).
    pub dynamic: &'a [f32],
    /// `[H · W]` predicted velocity (world units per unit of scene time), when the network predicts motion.
    pub velocity: Option<&'a [[f32; 3]]>,
}

/// How dynamic pixels are grouped.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClusterSettings {
    /// A pixel is dynamic when its dynamic probability is at least this.
    pub dynamic_threshold: f32,
    /// Largest difference of two neighbours' distances from the camera that still joins them, in pixel
    /// footprints at the nearer one's distance.
    pub depth_jump: f64,
    /// Smallest component kept, in pixels.
    pub min_pixels: usize,
}

impl Default for ClusterSettings {
    fn default() -> Self {
        Self { dynamic_threshold: 0.5, depth_jump: 8.0, min_pixels: 8 }
    }
}

/// One connected group of dynamic pixels of one view.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    /// Pixel indices (`row · W + column`) within the view, increasing.
    pub pixels: Vec<u32>,
    /// World-axis-aligned bounds of their points: `[min, max]`.
    pub bounds: [DVec3; 2],
}

impl Cluster {
    /// Diagonal of the bounds.
    pub fn extent(&self) -> f64 {
        (self.bounds[1] - self.bounds[0]).length()
    }
}

/// The clusters of `view`, largest first (ties by first pixel).
pub fn cluster_view(view: &ViewPoints, settings: &ClusterSettings) -> Vec<Cluster> {
    let (width, height) = (view.width, view.height);
    let point = |i: usize| DVec3::from_array(view.points[i].map(f64::from));
    let depth: Vec<f64> = (0..width * height).map(|i| point(i).distance(view.camera_centre)).collect();
    let dynamic = |i: usize| view.dynamic[i] >= settings.dynamic_threshold && depth[i].is_finite();
    let footprints = settings.depth_jump * view.pixel_angle;
    let joined = |a: usize, b: usize| {
        dynamic(a) && dynamic(b) && (depth[a] - depth[b]).abs() <= footprints * depth[a].min(depth[b])
    };
    let mut sets = UnionFind::new(width * height);
    for row in 0..height {
        for column in 0..width {
            let i = row * width + column;
            if column + 1 < width && joined(i, i + 1) {
                sets.union(i, i + 1);
            }
            if row + 1 < height && joined(i, i + width) {
                sets.union(i, i + width);
            }
        }
    }
    let (labels, count) = sets.labels();
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); count];
    for (i, &label) in labels.iter().enumerate() {
        if dynamic(i) {
            members[label].push(i as u32);
        }
    }
    let mut clusters: Vec<Cluster> = members
        .into_iter()
        .filter(|pixels| pixels.len() >= settings.min_pixels.max(1))
        .map(|pixels| {
            let bounds = pixels.iter().fold([DVec3::INFINITY, DVec3::NEG_INFINITY], |[lo, hi], &i| {
                let p = point(i as usize);
                [lo.min(p), hi.max(p)]
            });
            Cluster { pixels, bounds }
        })
        .collect();
    clusters.sort_by(|a, b| b.pixels.len().cmp(&a.pixels.len()).then(a.pixels[0].cmp(&b.pixels[0])));
    clusters
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 12 x 6 view looking down +z from the origin: two cars (pixels marked 1 at depth 10 and 2 at depth 20)
    /// side by side, touching in the image, on a static background.
    fn view_with_two_cars() -> (Vec<[f32; 3]>, Vec<f32>) {
        let layout = ["000000000000", "011110000000", "011112222200", "011112222200", "000002222200", "000000000000"];
        let mut points = Vec::new();
        let mut dynamic = Vec::new();
        for (row, line) in layout.iter().enumerate() {
            for (column, mark) in line.chars().enumerate() {
                let depth = match mark {
                    '1' => 10.0,
                    '2' => 20.0,
                    _ => 40.0,
                };
                points.push([column as f32 * depth / 10.0, row as f32 * depth / 10.0, depth]);
                dynamic.push(if mark == '0' { 0.1 } else { 0.9 });
            }
        }
        (points, dynamic)
    }

    fn view<'a>(points: &'a [[f32; 3]], dynamic: &'a [f32]) -> ViewPoints<'a> {
        ViewPoints {
            rig_camera: 0,
            time: 0.0,
            width: 12,
            height: 6,
            camera_centre: DVec3::ZERO,
            pixel_angle: 0.1,
            points,
            dynamic,
            velocity: None,
        }
    }

    #[test]
    fn a_depth_edge_separates_touching_objects() {
        let (points, dynamic) = view_with_two_cars();
        let clusters = cluster_view(&view(&points, &dynamic), &ClusterSettings { min_pixels: 3, ..Default::default() });
        assert_eq!(clusters.len(), 2, "{clusters:?}");
        assert_eq!(clusters[0].pixels.len(), 15, "the far car");
        assert_eq!(clusters[1].pixels.len(), 12, "the near car");
        assert!(clusters[1].bounds[0].z == 10.0 && clusters[1].bounds[1].z == 10.0);
        // Without the depth test they are one.
        let loose = ClusterSettings { depth_jump: 20.0, min_pixels: 3, ..Default::default() };
        assert_eq!(cluster_view(&view(&points, &dynamic), &loose).len(), 1);
    }

    #[test]
    fn small_components_and_static_views_give_no_cluster() {
        let (points, dynamic) = view_with_two_cars();
        let strict = ClusterSettings { min_pixels: 13, ..Default::default() };
        assert_eq!(cluster_view(&view(&points, &dynamic), &strict).len(), 1);
        let still = vec![0.0; dynamic.len()];
        assert!(cluster_view(&view(&points, &still), &ClusterSettings::default()).is_empty());
    }
}
