//! Bicubic resizing of 8-bit images: Catmull-Rom (`a = -0.5`) with the kernel widened when downscaling, as PIL's
//! `BICUBIC` resize that the release's preprocessing uses.
//!
//! A crate of its own for the build's sake: `fast_image_resize` instantiates its kernels per pixel type and
//! instruction set, most of the LLVM IR a crate calling it holds. The resize is typed (`Resizer::resize_typed`, the
//! call its untyped `resize` dispatches to), so that only the two pixel types used here are instantiated, not all
//! thirteen; and, depending on nothing else of the workspace, they compile while the rest of the build does.

use fast_image_resize::pixels::{U8, U8x3};
use fast_image_resize::{
    FilterType, PixelTrait, ResizeAlg, ResizeOptions, Resizer, images::TypedImage, images::TypedImageRef,
};

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
}

/// Why a resize was refused: the buffer does not hold `width x height` pixels, or a size is zero.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ResizeError(String);

/// Resizes `pixels` (row-major, `from = (width, height)`, interleaved as `layout`) to `to = (width, height)`.
pub fn resize(pixels: &[u8], layout: Pixels, from: (u32, u32), to: (u32, u32)) -> Result<Vec<u8>, ResizeError> {
    match layout {
        Pixels::Gray => resize_typed::<U8>(pixels, from, to),
        Pixels::Rgb => resize_typed::<U8x3>(pixels, from, to),
    }
}

/// [`resize`] for one pixel type `P`.
fn resize_typed<P: PixelTrait>(pixels: &[u8], from: (u32, u32), to: (u32, u32)) -> Result<Vec<u8>, ResizeError> {
    let expected = from.0 as usize * from.1 as usize * P::size();
    if pixels.len() != expected {
        return Err(ResizeError(format!(
            "an image buffer of {}x{}: {} bytes where {expected} were expected",
            from.0,
            from.1,
            pixels.len()
        )));
    }
    let source = TypedImageRef::<P>::from_buffer(from.0, from.1, pixels)
        .map_err(|e| ResizeError(format!("an image buffer of {}x{}: {e}", from.0, from.1)))?;
    let mut resized = vec![0u8; to.0 as usize * to.1 as usize * P::size()];
    let mut target = TypedImage::<P>::from_buffer(to.0, to.1, &mut resized)
        .map_err(|e| ResizeError(format!("a target buffer of {}x{}: {e}", to.0, to.1)))?;
    let options = ResizeOptions::new().resize_alg(ResizeAlg::Convolution(FilterType::CatmullRom));
    Resizer::new()
        .resize_typed(&source, &mut target, &options)
        .map_err(|e| ResizeError(format!("resizing {}x{} to {}x{}: {e}", from.0, from.1, to.0, to.1)))?;
    Ok(resized)
}

#[cfg(test)]
mod tests {
    use super::{Pixels, resize};

    #[test]
    fn a_flat_image_stays_flat_and_a_short_buffer_is_refused() {
        let grey = vec![77u8; 3 * 40 * 30];
        let resized = resize(&grey, Pixels::Rgb, (40, 30), (14, 10)).unwrap();
        assert_eq!(resized.len(), 3 * 14 * 10, "three bytes per pixel of the target");
        assert!(resized.iter().all(|&v| v == 77), "a constant image resizes to the same constant");
        let short = resize(&[0u8; 10], Pixels::Gray, (4, 4), (2, 2));
        assert!(short.is_err_and(|e| e.to_string().contains("4x4")), "the buffer's size is named");
    }
}
