//! Bicubic resizing of 8-bit images: Catmull-Rom (`a = -0.5`) with the kernel widened when downscaling, as PIL's
//! `BICUBIC` resize that the release's preprocessing uses.
//!
//! A crate of its own for the build's sake: `fast_image_resize` picks its kernels by pixel type and instruction set
//! at run time, so the one call below monomorphises all of them (about half of the LLVM IR the preprocessing crate
//! used to hold). Here, depending on nothing else of the workspace, they compile while the rest of the build does.

use fast_image_resize::{FilterType, PixelType, ResizeAlg, ResizeOptions, Resizer, images::Image};

/// The layout of a pixel: interleaved 8-bit channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pixels {
    /// One channel (masks).
    Gray,
    /// Red, green, blue.
    Rgb,
}

impl Pixels {
    /// Bytes per pixel.
    pub fn channels(self) -> usize {
        match self {
            Self::Gray => 1,
            Self::Rgb => 3,
        }
    }

    fn pixel_type(self) -> PixelType {
        match self {
            Self::Gray => PixelType::U8,
            Self::Rgb => PixelType::U8x3,
        }
    }
}

/// Why a resize was refused: the buffer does not hold `width x height` pixels, or a size is zero.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ResizeError(String);

/// Resizes `pixels` (row-major, `from = (width, height)`, interleaved as `layout`) to `to = (width, height)`.
pub fn resize(pixels: Vec<u8>, layout: Pixels, from: (u32, u32), to: (u32, u32)) -> Result<Vec<u8>, ResizeError> {
    let source = Image::from_vec_u8(from.0, from.1, pixels, layout.pixel_type())
        .map_err(|e| ResizeError(format!("an image buffer of {}x{}: {e}", from.0, from.1)))?;
    let mut target = Image::new(to.0, to.1, layout.pixel_type());
    let options = ResizeOptions::new().resize_alg(ResizeAlg::Convolution(FilterType::CatmullRom));
    Resizer::new()
        .resize(&source, &mut target, &options)
        .map_err(|e| ResizeError(format!("resizing {}x{} to {}x{}: {e}", from.0, from.1, to.0, to.1)))?;
    Ok(target.into_vec())
}

#[cfg(test)]
mod tests {
    use super::{Pixels, resize};

    #[test]
    fn a_flat_image_stays_flat_and_a_short_buffer_is_refused() {
        let grey = vec![77u8; 3 * 40 * 30];
        let resized = resize(grey, Pixels::Rgb, (40, 30), (14, 10)).unwrap();
        assert_eq!(resized.len(), 3 * 14 * 10, "three bytes per pixel of the target");
        assert!(resized.iter().all(|&v| v == 77), "a constant image resizes to the same constant");
        let short = resize(vec![0u8; 10], Pixels::Gray, (4, 4), (2, 2));
        assert!(short.is_err_and(|e| e.to_string().contains("4x4")), "the buffer's size is named");
    }
}
