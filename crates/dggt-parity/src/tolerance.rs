//! How large a difference from a reference output passes: a tolerance that is absolute for small references and
//! relative for large ones, `scale * max(1, max|reference|)` on the largest absolute difference.

/// The largest absolute difference allowed, relative to `max(1, max|reference|)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerance {
    pub scale: f64,
}

/// The network's outputs: `max(1e-4, 1e-4 * max|reference|)`.
pub const NETWORK: Tolerance = Tolerance { scale: 1e-4 };

/// The refiner's tensors: `5e-5 * max(1, max|reference|)`.
pub const REFINER: Tolerance = Tolerance { scale: 5e-5 };

impl Tolerance {
    /// The largest allowed difference for a reference whose largest magnitude is `max_reference`.
    pub fn allowed(self, max_reference: f64) -> f64 {
        self.scale * max_reference.max(1.0)
    }

    /// [`Tolerance::allowed`] computed in `f32`, for comparisons made in `f32`.
    pub fn allowed_f32(self, max_reference: f32) -> f32 {
        self.scale as f32 * max_reference.max(1.0)
    }
}
