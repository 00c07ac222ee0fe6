//! Decoding and encoding of camera images and masks.

use std::io::Cursor;
use std::path::Path;

use dggt_geom::ImageSize;
use image::{GrayImage, ImageFormat, RgbImage};

use crate::error::{DataError, Result};

fn decode(path: &Path) -> Result<image::DynamicImage> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    check_jpeg_is_complete(path, &bytes)?;
    image::load_from_memory(&bytes).map_err(|source| DataError::Image { path: path.to_owned(), source })
}

/// A JPEG (it starts with the SOI marker) must end with the EOI marker, trailing zero padding aside: the
/// decoder fills a truncated file's missing rows with grey instead of failing, which would train on garbage.
fn check_jpeg_is_complete(path: &Path, bytes: &[u8]) -> Result<()> {
    const SOI: [u8; 2] = [0xFF, 0xD8];
    const EOI: [u8; 2] = [0xFF, 0xD9];
    if !bytes.starts_with(&SOI) {
        return Ok(());
    }
    let end = bytes.iter().rposition(|&b| b != 0).map_or(0, |last| last + 1);
    if bytes[..end].ends_with(&EOI) {
        return Ok(());
    }
    Err(DataError::malformed(
        path,
        "a complete JPEG ending with the EOI marker FF D9",
        format!("a truncated file of {} bytes", bytes.len()),
    ))
}

/// Reads a camera image as 8-bit RGB (grayscale images are replicated to three channels).
pub fn read_rgb(path: &Path) -> Result<RgbImage> {
    Ok(decode(path)?.to_rgb8())
}

/// Reads an 8-bit mask (any colour type is reduced to luma).
pub fn read_gray(path: &Path) -> Result<GrayImage> {
    Ok(decode(path)?.to_luma8())
}

/// The size of an image, read from its header without decoding the pixels.
pub fn read_size(path: &Path) -> Result<ImageSize> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| DataError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| DataError::io(path, e))?;
    let (width, height) =
        reader.into_dimensions().map_err(|source| DataError::Image { path: path.to_owned(), source })?;
    ImageSize::new(width, height).map_err(|e| DataError::geometry(path, e))
}

/// Checks that an image has the size its calibration describes.
pub fn expect_size(path: &Path, actual: ImageSize, expected: ImageSize) -> Result<()> {
    if actual != expected {
        return Err(DataError::malformed(path, format!("an image of {expected} pixels"), format!("{actual}")));
    }
    Ok(())
}

/// Encodes RGB as baseline JPEG at `quality` (1-100) and writes it atomically. Deterministic.
pub fn write_jpeg(path: &Path, image: &RgbImage, quality: u8) -> Result<()> {
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality)
        .encode_image(image)
        .map_err(|source| DataError::Image { path: path.to_owned(), source })?;
    crate::io::write_atomically(path, &bytes)
}

/// Encodes an 8-bit grayscale PNG and writes it atomically.
pub fn write_png_gray(path: &Path, image: &GrayImage) -> Result<()> {
    let mut bytes = Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, ImageFormat::Png)
        .map_err(|source| DataError::Image { path: path.to_owned(), source })?;
    crate::io::write_atomically(path, &bytes.into_inner())
}
