//! Decoding and encoding of camera images and masks.

use std::io::Cursor;
use std::path::Path;

use dggt_geom::ImageSize;
use image::{DynamicImage, GrayImage, ImageBuffer, ImageFormat, Luma, RgbImage};

use crate::error::{DataError, Result};

/// A 16-bit single-channel image (an instance mask).
pub type Gray16Image = ImageBuffer<Luma<u16>, Vec<u16>>;

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

/// Reads a 16-bit grayscale PNG (an instance mask); any other colour type is an error naming the file, so that an
/// 8-bit mask is not read as instance keys.
pub fn read_gray16(path: &Path) -> Result<Gray16Image> {
    match decode(path)? {
        DynamicImage::ImageLuma16(image) => Ok(image),
        other => Err(DataError::malformed(path, "a 16-bit grayscale PNG", format!("{:?}", other.color()))),
    }
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
    write_png(path, image)
}

/// Encodes a 16-bit grayscale PNG and writes it atomically.
pub fn write_png_gray16(path: &Path, image: &Gray16Image) -> Result<()> {
    write_png(path, image)
}

fn write_png<P>(path: &Path, image: &ImageBuffer<P, Vec<P::Subpixel>>) -> Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
{
    let mut bytes = Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, ImageFormat::Png)
        .map_err(|source| DataError::Image { path: path.to_owned(), source })?;
    crate::io::write_atomically(path, &bytes.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_16_bit_mask_reads_back_and_an_8_bit_one_is_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let (wide, narrow) = (dir.path().join("keys.png"), dir.path().join("gray.png"));
        let keys = Gray16Image::from_fn(5, 3, |x, y| Luma([(x * 1000 + y) as u16 + 300]));
        write_png_gray16(&wide, &keys).unwrap();
        assert_eq!(read_gray16(&wide).unwrap(), keys);
        write_png_gray(&narrow, &GrayImage::from_pixel(5, 3, Luma([7]))).unwrap();
        let message = read_gray16(&narrow).unwrap_err().to_string();
        assert!(message.contains("gray.png") && message.contains("16-bit grayscale"), "{message}");
    }
}
