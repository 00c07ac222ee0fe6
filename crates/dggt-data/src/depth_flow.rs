//! Quarter-resolution depth and scene-flow maps (`depth_flows_4/{t}_{cam}.npy`).
//!
//! Shape `(H/4, W/4, 4)` float32: channel 0 is z-depth in metres (0 = no measurement), channels 1-3 the scene
//! flow of that surface point. Cell `(row, col)` covers the full-resolution pixels `4 row .. 4 row + 4` and
//! `4 col .. 4 col + 4`, so its centre is at continuous coordinates `(4 col + 2, 4 row + 2)`.

use std::path::Path;

use dggt_geom::ImageSize;

use crate::error::{DataError, Result};
use crate::npy::read_npy_f32;

/// Downsampling factor of the maps.
pub const DEPTH_FLOW_STRIDE: u32 = 4;

/// One depth-and-flow map.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFlowMap {
    /// Size of the quarter-resolution grid.
    pub size: ImageSize,
    /// Row-major z-depth, 0 where unknown.
    pub depth: Vec<f32>,
    /// Row-major scene flow.
    pub flow: Vec<[f32; 3]>,
}

impl DepthFlowMap {
    /// Reads a map and checks it against the full-resolution image size it belongs to.
    pub fn read(path: &Path, image_size: ImageSize) -> Result<Self> {
        let array = read_npy_f32(path)?;
        let expected =
            [(image_size.height / DEPTH_FLOW_STRIDE) as usize, (image_size.width / DEPTH_FLOW_STRIDE) as usize, 4];
        if array.shape != expected {
            return Err(DataError::malformed(
                path,
                format!("shape {expected:?} (a quarter of the {image_size} image, 4 channels)"),
                format!("{:?}", array.shape),
            ));
        }
        if let Some(i) = array.data.iter().position(|v| !v.is_finite()) {
            return Err(DataError::malformed(path, "finite values", format!("a non-finite value at index {i}")));
        }
        let depth = array.data.chunks_exact(4).map(|c| c[0]).collect();
        let flow = array.data.chunks_exact(4).map(|c| [c[1], c[2], c[3]]).collect();
        Ok(Self { size: ImageSize { width: expected[1] as u32, height: expected[0] as u32 }, depth, flow })
    }
}
