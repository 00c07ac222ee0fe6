//! Why a Gaussian is left out of a view, and the per-view counts that tell a training run what its scene costs.

use std::fmt;

/// The first rule (in this order) that removed a Gaussian from a view. A culled Gaussian is never binned into
/// tiles, contributes to no pixel of that view and gets no gradient from it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CullReason {
    /// A mean, quaternion, scale, colour or this view's opacity is NaN or infinite.
    NonFinite,
    /// Opacity below 1/255: no pixel could reach the compositing threshold.
    Transparent,
    /// Camera-space depth `z <= near_plane` (behind the camera or too close).
    NearPlane,
    /// Camera-space depth `z >= far_plane`.
    FarPlane,
    /// The projected 2D covariance is not positive definite or not representable (overflow).
    Degenerate,
    /// The bounding box of the projected Gaussian does not overlap the image.
    OutsideImage,
}

/// What happened to the Gaussians in one view.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CullStats {
    /// All Gaussians considered (`N`).
    pub gaussians: usize,
    /// Gaussians binned into at least one tile.
    pub kept: usize,
    pub non_finite: usize,
    pub transparent: usize,
    pub near_plane: usize,
    pub far_plane: usize,
    pub degenerate: usize,
    pub outside_image: usize,
    /// Number of (tile, Gaussian) pairs composited: the size of the view's sorted tile lists.
    pub tile_intersections: usize,
}

impl CullStats {
    /// Counts the outcome of every Gaussian of a view (`None` = kept).
    pub(crate) fn count(outcomes: &[Option<CullReason>], tile_intersections: usize) -> Self {
        let mut stats = CullStats { gaussians: outcomes.len(), tile_intersections, ..Default::default() };
        for outcome in outcomes {
            let counter = match outcome {
                None => &mut stats.kept,
                Some(CullReason::NonFinite) => &mut stats.non_finite,
                Some(CullReason::Transparent) => &mut stats.transparent,
                Some(CullReason::NearPlane) => &mut stats.near_plane,
                Some(CullReason::FarPlane) => &mut stats.far_plane,
                Some(CullReason::Degenerate) => &mut stats.degenerate,
                Some(CullReason::OutsideImage) => &mut stats.outside_image,
            };
            *counter += 1;
        }
        stats
    }

    /// Number of counters in [`to_counts`](Self::to_counts).
    pub const COUNTS: usize = 9;

    /// The counters in declaration order (`gaussians`, `kept`, the six reasons, `tile_intersections`): the row
    /// layout of the statistics tensor a tensor backend returns.
    pub fn to_counts(&self) -> [usize; Self::COUNTS] {
        [
            self.gaussians,
            self.kept,
            self.non_finite,
            self.transparent,
            self.near_plane,
            self.far_plane,
            self.degenerate,
            self.outside_image,
            self.tile_intersections,
        ]
    }

    /// The inverse of [`to_counts`](Self::to_counts).
    pub fn from_counts(counts: [usize; Self::COUNTS]) -> Self {
        let [
            gaussians,
            kept,
            non_finite,
            transparent,
            near_plane,
            far_plane,
            degenerate,
            outside_image,
            tile_intersections,
        ] = counts;
        Self {
            gaussians,
            kept,
            non_finite,
            transparent,
            near_plane,
            far_plane,
            degenerate,
            outside_image,
            tile_intersections,
        }
    }

    /// Gaussians removed for any reason.
    pub fn culled(&self) -> usize {
        self.gaussians - self.kept
    }
}

impl fmt::Display for CullStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} of {} Gaussians kept ({} tile intersections); culled: {} non-finite, {} transparent, {} near plane, \
             {} far plane, {} degenerate, {} outside the image",
            self.kept,
            self.gaussians,
            self.tile_intersections,
            self.non_finite,
            self.transparent,
            self.near_plane,
            self.far_plane,
            self.degenerate,
            self.outside_image
        )
    }
}
