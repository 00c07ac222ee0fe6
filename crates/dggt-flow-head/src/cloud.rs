//! One input time's points with their features, the two inputs of the flow head, and the errors the head reports
//! for bad input.
//!
//! A [`FrameCloud`] holds row-aligned tensors: `points` `[N, 3]`, the Gaussian means in world units (`x y z`), and
//! `features` `[N, C]`, the image features sampled at the same pixels ([`crate::sample_features`]). The points are
//! read back to the host for the neighbour search, and checked there: the head refuses a non-finite point with
//! an error naming its cloud and row rather than searching with it. Features are not read back (a non-finite
//! feature shows as a non-finite displacement, refused before the next neighbour search).

use burn::tensor::Tensor;

/// Which cloud a problem concerns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CloudRole {
    /// The points of time `ta` whose displacements are predicted.
    Query,
    /// The points of time `tb` the queries attend to.
    Target,
    /// Input view `i`'s cloud, prepared once for every pair it takes part in (either role).
    View(usize),
}

impl std::fmt::Display for CloudRole {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Query => f.write_str("query cloud"),
            Self::Target => f.write_str("target cloud"),
            Self::View(view) => write!(f, "cloud of input view {view}"),
        }
    }
}

/// Why the flow head refused its input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FlowError {
    #[error("the points of the {cloud} have {columns} columns, expected 3 (x y z)")]
    PointWidth { cloud: CloudRole, columns: usize },
    #[error("the {cloud} has {points} points but {features} feature rows")]
    RowMismatch { cloud: CloudRole, points: usize, features: usize },
    #[error("the features of the {cloud} have {found} channels, the head was configured for {expected}")]
    FeatureWidth { cloud: CloudRole, expected: usize, found: usize },
    #[error("point {row} of the {cloud} is not finite: {point:?}")]
    NonFinitePoint { cloud: CloudRole, row: usize, point: [f32; 3] },
    #[error("query {row}'s displacement became non-finite in refinement iteration {iteration}")]
    NonFiniteDisplacement { row: usize, iteration: usize },
    #[error("reading the points of the {cloud} back from the device failed: {reason}")]
    Readback { cloud: CloudRole, reason: String },
}

/// One time's points and their features, row by row.
#[derive(Debug, Clone)]
pub struct FrameCloud {
    /// `[N, 3]`: world-space points (`x y z`), in the reconstruction's units.
    pub points: Tensor<2>,
    /// `[N, C]`: the features of each point.
    pub features: Tensor<2>,
}

impl FrameCloud {
    pub fn new(points: Tensor<2>, features: Tensor<2>) -> Self {
        Self { points, features }
    }

    /// Rows (points).
    pub fn len(&self) -> usize {
        self.points.dims()[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Checks the shapes: three point columns, as many feature rows as points, `width` feature channels.
    pub fn check_shapes(&self, cloud: CloudRole, width: usize) -> Result<(), FlowError> {
        let [points, columns] = self.points.dims();
        let [features, found] = self.features.dims();
        if columns != 3 {
            return Err(FlowError::PointWidth { cloud, columns });
        }
        if points != features {
            return Err(FlowError::RowMismatch { cloud, points, features });
        }
        if found != width {
            return Err(FlowError::FeatureWidth { cloud, expected: width, found });
        }
        Ok(())
    }

    /// The points on the host, refused if any is not finite.
    pub fn host_points(&self, cloud: CloudRole) -> Result<Vec<[f32; 3]>, FlowError> {
        let rows = read_rows(self.points.clone()).map_err(|reason| FlowError::Readback { cloud, reason })?;
        match rows.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
            Some(row) => Err(FlowError::NonFinitePoint { cloud, row, point: rows[row] }),
            None => Ok(rows),
        }
    }
}

/// An `[N, 3]` tensor's rows on the host, in f32.
pub(crate) fn read_rows(tensor: Tensor<2>) -> Result<Vec<[f32; 3]>, String> {
    let values = tensor.try_into_vec_as::<f32>().map_err(|e| e.to_string())?;
    Ok(values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}
