//! Nearest-neighbour search over one cloud's points: on the host (an R*-tree, [`NeighbourSearch`]) or, on a CubeCL
//! device, by brute force where the points are (`device`, features `wgpu` / `cuda`). [`SearchPlace::for_points`]
//! says which the head uses.
//!
//! On the host the head reads the moved query positions back from the device and looks their neighbours up here.
//! Either way the rows are data, not part of the gradient (the neighbour set is piecewise constant in the
//! positions). Ties in distance are broken in whatever order the tree visits them (on the device: target order).

#[cfg(any(feature = "wgpu", feature = "cuda"))]
pub mod device;

use burn::tensor::Tensor;
use rstar::RTree;
use rstar::primitives::GeomWithData;

/// Where the head looks a cloud's neighbours up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SearchPlace {
    /// The host's R*-tree, from positions read back.
    Host,
    /// The points' CubeCL device, by brute force (`device::k_nearest`).
    #[cfg(any(feature = "wgpu", feature = "cuda"))]
    Device,
}

impl SearchPlace {
    /// The device for `f32` points on a CubeCL device (with the `wgpu` / `cuda` features), the host otherwise.
    pub fn for_points(points: &Tensor<2>) -> Self {
        #[cfg(any(feature = "wgpu", feature = "cuda"))]
        if points.dtype() == burn::tensor::DType::F32
            && matches!(points.device().without_autodiff().as_dispatch(), burn::backend::DispatchDevice::Cube(_))
        {
            return Self::Device;
        }
        let _ = points;
        Self::Host
    }
}

/// A point with its row in the cloud.
type Entry = GeomWithData<[f32; 3], usize>;

/// The points of one cloud, indexed for nearest-neighbour queries.
pub struct NeighbourSearch {
    tree: RTree<Entry>,
}

impl NeighbourSearch {
    pub fn new(points: &[[f32; 3]]) -> Self {
        Self { tree: RTree::bulk_load(points.iter().enumerate().map(|(row, p)| Entry::new(*p, row)).collect()) }
    }

    /// Points indexed.
    pub fn len(&self) -> usize {
        self.tree.size()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The rows of the `k` points nearest each query, nearest first, query after query: `queries.len() * k`
    /// entries. `k` must not exceed [`Self::len`].
    pub fn k_nearest(&self, queries: &[[f32; 3]], k: usize) -> Vec<usize> {
        assert!(k <= self.len(), "{k} neighbours asked of {} points", self.len());
        queries.iter().flat_map(|q| self.tree.nearest_neighbor_iter(*q).take(k).map(|e| e.data)).collect()
    }

    /// The nearest point to `query` that does not coincide with it, as its row and squared distance; `None`
    /// when every point coincides with `query`.
    pub fn nearest_distinct(&self, query: [f32; 3]) -> Option<(usize, f32)> {
        self.tree
            .nearest_neighbor_iter_with_distance_2(query)
            .find(|(_, distance_2)| *distance_2 > 0.0)
            .map(|(entry, distance_2)| (entry.data, distance_2))
    }
}

/// Squared Euclidean distance.
pub fn distance_2(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Every point's squared distance to `query`, sorted, the `k` smallest.
    fn brute_force(points: &[[f32; 3]], query: [f32; 3], k: usize) -> Vec<f32> {
        let mut d: Vec<f32> = points.iter().map(|p| distance_2(*p, query)).collect();
        d.sort_by(f32::total_cmp);
        d.truncate(k);
        d
    }

    fn point() -> impl Strategy<Value = [f32; 3]> {
        // A coarse grid as well as a continuum, so that ties and duplicates occur.
        prop_oneof![
            prop::array::uniform3(-10.0f32..10.0),
            prop::array::uniform3(-2i32..3).prop_map(|a| a.map(|v| v as f32))
        ]
    }

    proptest! {
        #[test]
        fn k_nearest_matches_brute_force(
            points in prop::collection::vec(point(), 1..60),
            queries in prop::collection::vec(point(), 1..12),
            k in 1usize..20,
        ) {
            let k = k.min(points.len());
            let search = NeighbourSearch::new(&points);
            let found = search.k_nearest(&queries, k);
            prop_assert_eq!(found.len(), queries.len() * k);
            for (query, rows) in queries.iter().zip(found.chunks_exact(k)) {
                let mut unique = rows.to_vec();
                unique.sort_unstable();
                unique.dedup();
                prop_assert_eq!(unique.len(), k, "a row returned twice: {:?}", rows);
                let distances: Vec<f32> = rows.iter().map(|&r| distance_2(points[r], *query)).collect();
                prop_assert_eq!(distances, brute_force(&points, *query, k));
            }
        }

        #[test]
        fn nearest_distinct_matches_brute_force(points in prop::collection::vec(point(), 1..40), query in point()) {
            let expected = points.iter().map(|p| distance_2(*p, query)).filter(|d| *d > 0.0).min_by(f32::total_cmp);
            let found = NeighbourSearch::new(&points).nearest_distinct(query);
            prop_assert_eq!(found.map(|(_, d)| d), expected);
            if let Some((row, d)) = found {
                prop_assert_eq!(distance_2(points[row], query), d);
            }
        }
    }
}
