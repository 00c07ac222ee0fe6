//! The length the head measures offsets in: the target cloud's sampling spacing, so that the head does not
//! depend on the reconstruction's unit (a scene reconstructed ten times larger gives ten times the displacement).
//!
//! The spacing is the median, over target points, of the distance to the nearest distinct target point (at most
//! [`SPACING_SAMPLES`] target points, evenly strided, are measured). It is a local length, of the order of the
//! offsets between a query and its neighbours, whatever the extent of the scene. The points of the median pair
//! are chosen on the host; the length itself is computed from the point tensors, so it is part of the gradient.
//! Degenerate clouds (one target point, or all coincident) fall back to the RMS distance of both clouds' points
//! about their joint centroid.
//!
//! The length is computed once per forward pass, from the whole clouds, before the queries are split into chunks,
//! so the chunking does not change it.

use burn::tensor::{Int, Tensor, TensorData};

use crate::neighbours::NeighbourSearch;

/// Most target points whose nearest-neighbour distance enters the median.
pub const SPACING_SAMPLES: usize = 1024;

/// Where the length comes from, decided on the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScaleSource {
    /// The distance between these two target rows: the median nearest-distinct-neighbour pair.
    Spacing { row: usize, neighbour: usize },
    /// The RMS distance of both clouds' points about their joint centroid.
    Spread,
}

impl ScaleSource {
    /// The median nearest-distinct-neighbour pair of the target points (`search` indexes them).
    pub fn of_target(points: &[[f32; 3]], search: &NeighbourSearch) -> Self {
        let stride = points.len().div_ceil(SPACING_SAMPLES).max(1);
        let mut pairs: Vec<(f32, usize, usize)> = (0..points.len())
            .step_by(stride)
            .filter_map(|row| search.nearest_distinct(points[row]).map(|(neighbour, d2)| (d2, row, neighbour)))
            .collect();
        if pairs.is_empty() {
            return Self::Spread;
        }
        let middle = (pairs.len() - 1) / 2;
        let (_, &mut (_, row, neighbour), _) = pairs.select_nth_unstable_by(middle, |a, b| a.0.total_cmp(&b.0));
        Self::Spacing { row, neighbour }
    }

    /// The length as a `[1]` tensor, differentiable in the points (`[N, 3]` each).
    pub fn length(self, query: &Tensor<2>, target: &Tensor<2>) -> Tensor<1> {
        let length = match self {
            Self::Spacing { row, neighbour } => {
                let rows = Tensor::<1, Int>::from_data(
                    TensorData::new(vec![row as i64, neighbour as i64], [2]),
                    &target.device(),
                );
                let pair = target.clone().select(0, rows);
                let difference = pair.clone().narrow(0, 0, 1) - pair.narrow(0, 1, 1);
                difference.powi_scalar(2).sum().sqrt()
            }
            Self::Spread => {
                let points = Tensor::cat(vec![query.clone(), target.clone()], 0);
                let centred = points.clone() - points.mean_dim(0);
                centred.powi_scalar(2).sum_dim(1).mean().sqrt()
            }
        };
        // All points coincide: any positive length gives the same (zero) offsets.
        length.clamp_min(f32::MIN_POSITIVE)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::FrameCloud;
    use burn::tensor::Device;

    fn cloud(points: &[[f32; 3]]) -> FrameCloud {
        let device = Device::flex();
        let flat: Vec<f32> = points.iter().flatten().copied().collect();
        FrameCloud::new(
            Tensor::from_data(TensorData::new(flat, [points.len(), 3]), &device),
            Tensor::zeros([points.len(), 1], &device),
        )
    }

    fn length_of(query: &[[f32; 3]], target: &[[f32; 3]]) -> f32 {
        let source = ScaleSource::of_target(target, &NeighbourSearch::new(target));
        source.length(&cloud(query).points, &cloud(target).points).into_scalar::<f32>()
    }

    #[test]
    fn the_spacing_is_the_median_nearest_distinct_distance() {
        // Nearest-distinct distances 1, 1, 2, 3, 4, 4 (the duplicate at 10 is skipped): lower median 2.
        let target = [0.0, 1.0, 3.0, 6.0, 10.0, 10.0].map(|x| [x, 0.0, 0.0]);
        let search = NeighbourSearch::new(&target);
        assert!(matches!(ScaleSource::of_target(&target, &search), ScaleSource::Spacing { .. }));
        assert_eq!(length_of(&[[100.0, 0.0, 0.0]], &target), 2.0);
    }

    #[test]
    fn a_single_target_point_uses_the_spread_of_both_clouds() {
        let target = [[1.0, 0.0, 0.0]];
        assert_eq!(ScaleSource::of_target(&target, &NeighbourSearch::new(&target)), ScaleSource::Spread);
        // Centroid at the origin, both points at distance 1.
        assert_eq!(length_of(&[[-1.0, 0.0, 0.0]], &target), 1.0);
        assert!(length_of(&[[1.0, 0.0, 0.0]], &target) > 0.0);
    }
}
