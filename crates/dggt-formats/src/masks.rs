//! Per-pixel maps as 8-bit grayscale PNG: probabilities (the dynamic map) as `round(255 p)`, binary masks
//! (sky) as 0 or 255, as scene exports store their masks.

use std::path::Path;

use dggt_geom::ImageSize;
use image::GrayImage;

use crate::FormatError;

/// Writes probabilities in `[0, 1]` (clamped; non-finite values as 0), row-major.
pub fn write_probability_png(path: &Path, size: ImageSize, probability: &[f32]) -> Result<(), FormatError> {
    let values = probability.iter().map(|&p| if p.is_finite() { (p.clamp(0.0, 1.0) * 255.0).round() as u8 } else { 0 });
    write_gray(path, size, values.collect())
}

/// Writes a binary mask: 255 where `mask` is set.
pub fn write_binary_png(path: &Path, size: ImageSize, mask: &[bool]) -> Result<(), FormatError> {
    write_gray(path, size, mask.iter().map(|&m| if m { 255 } else { 0 }).collect())
}

fn write_gray(path: &Path, size: ImageSize, values: Vec<u8>) -> Result<(), FormatError> {
    if values.len() != size.area() {
        return Err(FormatError::invalid(path, format!("{} mask values for a {size} image", values.len())));
    }
    let image = GrayImage::from_raw(size.width, size.height, values)
        .ok_or_else(|| FormatError::invalid(path, "mask buffer does not fill the image"))?;
    crate::write_png(path, &image.into())
}

/// Reads an 8-bit grayscale PNG as values in `[0, 1]`.
pub fn read_mask_png(path: &Path) -> Result<(ImageSize, Vec<f32>), FormatError> {
    let bytes = crate::read_file(path)?;
    let image = image::load_from_memory(&bytes).map_err(|e| FormatError::malformed(path, "a PNG", e.to_string()))?;
    let image::DynamicImage::ImageLuma8(gray) = image else {
        return Err(FormatError::malformed(path, "an 8-bit grayscale PNG", format!("{:?}", image.color())));
    };
    let size = ImageSize::new(gray.width(), gray.height()).map_err(|e| FormatError::invalid(path, e.to_string()))?;
    Ok((size, gray.as_raw().iter().map(|&v| v as f32 / 255.0).collect()))
}
