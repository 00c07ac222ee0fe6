//! Pinhole intrinsics, image sizes and the pixel-coordinate convention.

use glam::{DMat3, DVec2, DVec3};
use serde::{Deserialize, Serialize};

use crate::GeomError;

/// Width and height of an image in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ImageSize {
    pub width: u32,
    pub height: u32,
}

impl ImageSize {
    pub fn new(width: u32, height: u32) -> Result<Self, GeomError> {
        if width == 0 || height == 0 {
            return Err(GeomError::InvalidImageSize { width, height });
        }
        Ok(Self { width, height })
    }

    /// Number of pixels.
    pub fn area(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

impl std::fmt::Display for ImageSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

/// Where pixel `(column, row)` sits in continuous image coordinates.
///
/// Intrinsics in this project follow the COLMAP / gsplat convention: the image spans `[0, W] x [0, H]`, so
/// scaling an image by `s` scales `fx, fy, cx, cy` by `s`. Pixel *centres* are then at half-integers
/// ([`PixelConvention::Centred`]). The DGGT release unprojects its depth maps at the integer coordinates
/// `(column, row)` instead ([`PixelConvention::Integer`]); its weights were trained that way, so the network
/// code uses that convention explicitly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelConvention {
    /// Pixel `(c, r)` is at `(c, r)`: the release's depth unprojection.
    Integer,
    /// Pixel `(c, r)` is at `(c + 0.5, r + 0.5)`: the rasteriser and the synthetic ray caster.
    Centred,
}

impl PixelConvention {
    /// Continuous image coordinates of the pixel at `column`, `row`.
    pub fn coordinates(self, column: u32, row: u32) -> DVec2 {
        let offset = match self {
            PixelConvention::Integer => 0.0,
            PixelConvention::Centred => 0.5,
        };
        DVec2::new(column as f64 + offset, row as f64 + offset)
    }
}

/// Pinhole intrinsics in pixels (no distortion). Projection of a camera-space point `(x, y, z)` with `z > 0`:
/// `u = fx x / z + cx`, `v = fy y / z + cy`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PinholeIntrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl PinholeIntrinsics {
    /// Validated constructor: all values finite and both focal lengths positive.
    pub fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Result<Self, GeomError> {
        let k = Self { fx, fy, cx, cy };
        k.validate()?;
        Ok(k)
    }

    /// Checks the invariants of [`PinholeIntrinsics::new`] on a value built directly.
    pub fn validate(&self) -> Result<(), GeomError> {
        if ![self.fx, self.fy, self.cx, self.cy].iter().all(|v| v.is_finite()) {
            return Err(GeomError::NonFinite { what: "pinhole intrinsics" });
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(GeomError::InvalidIntrinsics {
                detail: format!("focal lengths must be positive, got fx={} fy={}", self.fx, self.fy),
            });
        }
        Ok(())
    }

    /// Reads a 3x3 calibration matrix given as rows, checking its pinhole structure (zero skew, `[0 0 1]` last row).
    pub fn from_rows(rows: [[f64; 3]; 3]) -> Result<Self, GeomError> {
        if rows.iter().flatten().any(|v| !v.is_finite()) {
            return Err(GeomError::NonFinite { what: "3x3 intrinsic matrix" });
        }
        let structural = [rows[0][1], rows[1][0], rows[2][0], rows[2][1], rows[2][2] - 1.0];
        if structural.iter().any(|v| v.abs() > 1e-9) {
            return Err(GeomError::InvalidIntrinsics {
                detail: format!("expected [[fx,0,cx],[0,fy,cy],[0,0,1]], got {rows:?}"),
            });
        }
        Self::new(rows[0][0], rows[1][1], rows[0][2], rows[1][2])
    }

    /// The calibration matrix `K` (glam, column-major storage).
    pub fn matrix(&self) -> DMat3 {
        DMat3::from_cols(
            DVec3::new(self.fx, 0.0, 0.0),
            DVec3::new(0.0, self.fy, 0.0),
            DVec3::new(self.cx, self.cy, 1.0),
        )
    }

    /// `K` as rows in `f32`, for tensors.
    pub fn to_rows_f32(&self) -> [[f32; 3]; 3] {
        [[self.fx as f32, 0.0, self.cx as f32], [0.0, self.fy as f32, self.cy as f32], [0.0, 0.0, 1.0]]
    }

    /// Projects a camera-space point (OpenCV axes) to continuous pixel coordinates; `None` unless `z > 0`.
    pub fn project(&self, point: DVec3) -> Option<DVec2> {
        (point.z > 0.0)
            .then(|| DVec2::new(self.fx * point.x / point.z + self.cx, self.fy * point.y / point.z + self.cy))
    }

    /// The camera-space point at z-depth `depth` behind continuous pixel coordinates `pixel`.
    pub fn unproject(&self, pixel: DVec2, depth: f64) -> DVec3 {
        DVec3::new((pixel.x - self.cx) * depth / self.fx, (pixel.y - self.cy) * depth / self.fy, depth)
    }

    /// Intrinsics after resizing the image by `sx` horizontally and `sy` vertically.
    pub fn scaled(&self, sx: f64, sy: f64) -> Self {
        Self { fx: self.fx * sx, fy: self.fy * sy, cx: self.cx * sx, cy: self.cy * sy }
    }

    /// Intrinsics after cropping `left` pixels from the left edge and `top` from the top edge.
    pub fn cropped(&self, left: f64, top: f64) -> Self {
        Self { cx: self.cx - left, cy: self.cy - top, ..*self }
    }

    /// Vertical and horizontal field of view in radians, `(fov_h, fov_w)`, as VGGT defines them:
    /// `fov_h = 2 atan(H / (2 fy))`, `fov_w = 2 atan(W / (2 fx))`.
    pub fn fov(&self, size: ImageSize) -> (f64, f64) {
        (2.0 * (size.height as f64 / (2.0 * self.fy)).atan(), 2.0 * (size.width as f64 / (2.0 * self.fx)).atan())
    }

    /// Intrinsics with the given fields of view and the principal point at the image centre (VGGT's decoding).
    pub fn from_fov(fov_h: f64, fov_w: f64, size: ImageSize) -> Result<Self, GeomError> {
        let (w, h) = (size.width as f64, size.height as f64);
        Self::new((w / 2.0) / (fov_w / 2.0).tan(), (h / 2.0) / (fov_h / 2.0).tan(), w / 2.0, h / 2.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_values() {
        assert!(PinholeIntrinsics::new(f64::NAN, 1.0, 0.0, 0.0).is_err());
        assert!(PinholeIntrinsics::new(-5.0, 1.0, 0.0, 0.0).is_err());
        assert!(PinholeIntrinsics::from_rows([[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]).is_err());
        assert!(ImageSize::new(0, 3).is_err());
    }

    #[test]
    fn scaling_preserves_the_ray_of_the_image_corner() {
        let k = PinholeIntrinsics::new(500.0, 480.0, 320.0, 240.0).unwrap();
        let s = k.scaled(0.25, 0.5);
        let ray = k.unproject(DVec2::new(640.0, 480.0), 1.0);
        let ray_scaled = s.unproject(DVec2::new(160.0, 240.0), 1.0);
        assert!(ray.abs_diff_eq(ray_scaled, 1e-12));
    }

    #[test]
    fn fov_round_trip() {
        let size = ImageSize::new(518, 350).unwrap();
        let k = PinholeIntrinsics::new(300.0, 310.0, 259.0, 175.0).unwrap();
        let (fh, fw) = k.fov(size);
        let back = PinholeIntrinsics::from_fov(fh, fw, size).unwrap();
        assert!((back.fx - k.fx).abs() < 1e-9 && (back.fy - k.fy).abs() < 1e-9);
    }
}
