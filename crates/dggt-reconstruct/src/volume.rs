//! How much a reconstruction may write, checked before any work: the largest output the requested times could
//! give (every render as raw RGB, every input pixel's Gaussian in the static PLY, in each per-time dynamic PLY
//! and in the saved scene, the per-view maps) must stay under a bound, so that a mistyped `--every` or
//! `--times` is refused rather than filling a disk for minutes. The times themselves are checked by
//! [`crate::times`].

use std::fmt;

use dggt_formats::ply::INRIA_PROPERTIES;
use dggt_geom::ImageSize;

/// A gigabyte (10^9 bytes), the unit of the bound.
pub const GB: u64 = 1_000_000_000;
/// The bound unless told otherwise.
pub const DEFAULT_MAX_OUTPUT_BYTES: u64 = 10 * GB;

/// Bytes per Gaussian in a PLY file (float32 properties).
const PLY_VERTEX_BYTES: u64 = INRIA_PROPERTIES.len() as u64 * 4;
/// Bytes per pixel of an input view's files at most: the image (RGB), depth as `.npy` (float32) and 16-bit
/// PNG, the dynamic and sky masks.
const MAP_BYTES_PER_PIXEL: u64 = 3 + 4 + 2 + 1 + 1;
/// Bytes per input pixel of the saved scene (`scene.safetensors`) at most: twenty-six float32 values of its
/// Gaussian (mean, rotation, scale, colour, opacity, lifespan, time, dynamic logit, velocity, and the learnt
/// flow to the next and the previous input) and its instance label.
const SCENE_BYTES_PER_PIXEL: u64 = 26 * 4 + 4;
/// Bytes per pixel of a render at most (raw RGB; PNG compresses it).
const RENDER_BYTES_PER_PIXEL: u64 = 3;

/// What a reconstruction would write at most.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputEstimate {
    pub views: usize,
    pub cameras: usize,
    pub times: usize,
    pub size: ImageSize,
    pub bytes: u64,
}

impl OutputEstimate {
    /// The largest output of `views` input views from `cameras` cameras rendered at `times` times, at the
    /// network's input size `size`.
    pub fn new(views: usize, cameras: usize, times: usize, size: ImageSize) -> Self {
        let pixels = size.width as u64 * size.height as u64;
        let (views_n, cameras_n, times_n) = (views as u64, cameras as u64, times as u64);
        let per_view = pixels * (MAP_BYTES_PER_PIXEL + PLY_VERTEX_BYTES + SCENE_BYTES_PER_PIXEL);
        let per_time = cameras_n * pixels * (RENDER_BYTES_PER_PIXEL + PLY_VERTEX_BYTES);
        let bytes = views_n.saturating_mul(per_view).saturating_add(times_n.saturating_mul(per_time));
        Self { views, cameras, times, size, bytes }
    }

    /// Refused when over `max_bytes`.
    pub fn check(self, max_bytes: u64) -> Result<(), OutputTooLarge> {
        if self.bytes <= max_bytes {
            return Ok(());
        }
        Err(OutputTooLarge { estimate: self, max_bytes })
    }
}

/// An estimate over the bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputTooLarge {
    pub estimate: OutputEstimate,
    pub max_bytes: u64,
}

impl fmt::Display for OutputTooLarge {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the outputs could take {}, over the bound of {}: ask for fewer times (--times, --every), frames or \
             cameras, or raise the bound with --max-output-gb",
            self.estimate,
            gigabytes(self.max_bytes)
        )
    }
}

impl fmt::Display for OutputEstimate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "up to {} ({} render times x {} cameras and {} input views at {})",
            gigabytes(self.bytes),
            self.times,
            self.cameras,
            self.views,
            self.size
        )
    }
}

/// `bytes` in gigabytes, in words.
pub fn gigabytes(bytes: u64) -> String {
    format!("{:.2} GB", bytes as f64 / GB as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_over_the_bound_are_refused() {
        let size = ImageSize { width: 518, height: 294 };
        let estimate = OutputEstimate::new(6, 3, 100_001, size);
        assert!(estimate.bytes > 1000 * GB, "{estimate}");
        let error = estimate.check(DEFAULT_MAX_OUTPUT_BYTES).unwrap_err().to_string();
        assert!(error.contains("100001 render times") && error.contains("--max-output-gb"), "{error}");
        OutputEstimate::new(6, 3, 21, size).check(DEFAULT_MAX_OUTPUT_BYTES).unwrap();
    }
}
