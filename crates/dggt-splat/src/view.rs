//! The cameras a batch is rendered from: world-to-camera extrinsics (OpenCV axes) and pinhole intrinsics, all
//! views of a batch sharing one image size so that the outputs stack into `[V, H, W, ...]` buffers.

use dggt_geom::ImageSize;

use crate::error::{SplatError, expect_len};

/// One camera: `p_cam = R p_world + t` with `world_to_camera = [R | t]` as rows, and pinhole intrinsics in
/// pixels (`u = fx x / z + cx`, image spanning `[0, W] x [0, H]`, pixel centres at half-integers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinholeView {
    pub world_to_camera: [[f32; 4]; 3],
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl PinholeView {
    /// The rotation block as rows, in `f64`.
    pub(crate) fn rotation(&self) -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| self.world_to_camera[i][j] as f64))
    }

    /// The translation, in `f64`.
    pub(crate) fn translation(&self) -> [f64; 3] {
        std::array::from_fn(|i| self.world_to_camera[i][3] as f64)
    }

    fn validate(&self, view: usize) -> Result<(), SplatError> {
        let finite =
            self.world_to_camera.iter().flatten().chain(&[self.fx, self.fy, self.cx, self.cy]).all(|v| v.is_finite());
        if !finite {
            return Err(SplatError::InvalidView { view, detail: "non-finite extrinsics or intrinsics".into() });
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(SplatError::InvalidView {
                view,
                detail: format!("focal lengths must be positive, got fx={} fy={}", self.fx, self.fy),
            });
        }
        Ok(())
    }
}

/// `V` cameras rendered together at one image size.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewBatch {
    views: Vec<PinholeView>,
    size: ImageSize,
}

/// Largest deviation from `[0, 0, 0, 1]` accepted in the last row of a 4x4 view matrix.
const HOMOGENEOUS_ROW_TOLERANCE: f32 = 1e-6;

impl ViewBatch {
    /// Checks every camera: finite values and positive focal lengths.
    pub fn new(views: Vec<PinholeView>, size: ImageSize) -> Result<Self, SplatError> {
        for (v, view) in views.iter().enumerate() {
            view.validate(v)?;
        }
        Ok(Self { views, size })
    }

    /// From the tensors gsplat takes: `viewmats` `[V, 4, 4]` world-to-camera, row-major, last row `[0, 0, 0, 1]`;
    /// `intrinsics` `[V, 3, 3]` pinhole `K`, row-major (`[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`; skew ignored).
    pub fn from_matrices(viewmats: &[f32], intrinsics: &[f32], size: ImageSize) -> Result<Self, SplatError> {
        let count = viewmats.len() / 16;
        expect_len("viewmats", viewmats, count, 16, "[V, 4, 4]")?;
        expect_len("intrinsics", intrinsics, count, 9, "[V, 3, 3]")?;
        let views = (0..count)
            .map(|v| {
                let m = &viewmats[16 * v..16 * (v + 1)];
                let last_row = [m[12], m[13], m[14], m[15] - 1.0];
                if last_row.iter().any(|x| x.is_nan() || x.abs() > HOMOGENEOUS_ROW_TOLERANCE) {
                    return Err(SplatError::InvalidView {
                        view: v,
                        detail: format!("last row of the view matrix is {:?}, expected [0, 0, 0, 1]", &m[12..]),
                    });
                }
                let k = &intrinsics[9 * v..9 * (v + 1)];
                Ok(PinholeView {
                    world_to_camera: std::array::from_fn(|i| std::array::from_fn(|j| m[4 * i + j])),
                    fx: k[0],
                    fy: k[4],
                    cx: k[2],
                    cy: k[5],
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Self::new(views, size)
    }

    /// Number of views `V`.
    pub fn len(&self) -> usize {
        self.views.len()
    }

    pub fn is_empty(&self) -> bool {
        self.views.is_empty()
    }

    pub fn size(&self) -> ImageSize {
        self.size
    }

    pub fn views(&self) -> &[PinholeView] {
        &self.views
    }

    pub(crate) fn width(&self) -> usize {
        self.size.width as usize
    }

    pub(crate) fn height(&self) -> usize {
        self.size.height as usize
    }
}
