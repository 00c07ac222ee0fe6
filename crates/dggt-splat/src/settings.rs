//! Rasteriser settings: clipping planes, the 2D blur, the tile size, the background colour and which depth a
//! pixel reports.

use crate::constants::{DEFAULT_EPS2D, DEFAULT_FAR_PLANE, DEFAULT_NEAR_PLANE, DEFAULT_TILE_SIZE, MAX_TILE_SIZE};
use crate::error::SplatError;

/// Which depth each pixel reports.
///
/// The release renders (and trains on) the expected depth. At a depth edge a pixel sees a near and a far surface
/// through one another, and their blend lies on neither: the median depth is the depth of a surface the pixel
/// sees. Both are camera-space `z`, 0 where nothing is drawn.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum DepthStatistic {
    /// `Σ w z / max(alpha, 1e-10)`: differentiable, the release's.
    #[default]
    Expected,
    /// The depth of the footprint whose blending first brings the pixel's transmittance to one half or below
    /// (the median of the blending weights along the ray); the expected depth where the pixel never gets that
    /// opaque. A constant of the render: it carries no gradient (the host backward refuses a depth gradient
    /// with it; [`render`](crate::render) returns it detached).
    Median,
}

/// How a batch is rasterised. The defaults are gsplat's (and DGGT's): near 0.01, far 1e10, eps2d 0.3,
/// 16x16 tiles, black background, expected depth.
#[derive(Debug, Clone, PartialEq)]
pub struct RasterSettings {
    /// Gaussians with camera-space `z <= near_plane` are culled.
    pub near_plane: f32,
    /// Gaussians with camera-space `z >= far_plane` are culled.
    pub far_plane: f32,
    /// Added to the diagonal of every projected 2D covariance (a one-pixel-scale low-pass filter; "classic"
    /// mode: the opacity is not compensated for it).
    pub eps2d: f32,
    /// Side of the square screen tiles Gaussians are binned into, 1 to [`MAX_TILE_SIZE`].
    pub tile_size: u32,
    /// `[K]` colour behind the Gaussians, composited with the final transmittance; `None` is black.
    pub background: Option<Vec<f32>>,
    /// The largest single device buffer the GPU rasteriser may allocate, in bytes; `None` is the device's own
    /// limit (the lower of the two applies). Views whose tile intersections would not fit one buffer are
    /// rendered in batches of views that do. The host ignores it. Lowering it is for tests of the batching.
    pub max_buffer_bytes: Option<u64>,
    /// Which depth the depth image holds.
    pub depth: DepthStatistic,
}

impl Default for RasterSettings {
    fn default() -> Self {
        Self {
            near_plane: DEFAULT_NEAR_PLANE,
            far_plane: DEFAULT_FAR_PLANE,
            eps2d: DEFAULT_EPS2D,
            tile_size: DEFAULT_TILE_SIZE,
            background: None,
            max_buffer_bytes: None,
            depth: DepthStatistic::Expected,
        }
    }
}

impl RasterSettings {
    /// Checks the settings for `channels` colour channels.
    pub(crate) fn validate(&self, channels: usize) -> Result<(), SplatError> {
        let invalid = |detail: String| Err(SplatError::InvalidSettings { detail });
        if !(self.near_plane.is_finite() && self.near_plane >= 0.0) {
            return invalid(format!("near_plane must be finite and >= 0, got {}", self.near_plane));
        }
        if self.far_plane.is_nan() || self.far_plane <= self.near_plane {
            return invalid(format!("far_plane ({}) must exceed near_plane ({})", self.far_plane, self.near_plane));
        }
        if !(self.eps2d.is_finite() && self.eps2d >= 0.0) {
            return invalid(format!("eps2d must be finite and >= 0, got {}", self.eps2d));
        }
        if !(1..=MAX_TILE_SIZE).contains(&self.tile_size) {
            return invalid(format!("tile_size must be in 1..={MAX_TILE_SIZE}, got {}", self.tile_size));
        }
        if let Some(background) = &self.background {
            if background.len() != channels {
                return Err(SplatError::Shape {
                    tensor: "background",
                    expected: format!("{channels} ([K])"),
                    actual: background.len(),
                });
            }
            if background.iter().any(|v| !v.is_finite()) {
                return Err(SplatError::NonFinite { what: "background" });
            }
        }
        Ok(())
    }

    /// The background as `[K]` values (zeros when unset).
    pub(crate) fn background_or_black(&self, channels: usize) -> Vec<f32> {
        self.background.clone().unwrap_or_else(|| vec![0.0; channels])
    }
}
