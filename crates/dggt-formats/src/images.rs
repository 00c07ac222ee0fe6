//! RGB frames (renders, the network's inputs) as 8-bit PNG, from and to interleaved `[H, W, 3]` values in
//! `[0, 1]` (clamped, rounded).

use std::path::Path;

use dggt_geom::ImageSize;
use image::RgbImage;

use crate::FormatError;

/// Writes interleaved RGB in `[0, 1]` (non-finite values as 0).
pub fn write_rgb_png(path: &Path, size: ImageSize, rgb: &[f32]) -> Result<(), FormatError> {
    if rgb.len() != 3 * size.area() {
        return Err(FormatError::invalid(path, format!("{} RGB values for a {size} image", rgb.len())));
    }
    let bytes: Vec<u8> =
        rgb.iter().map(|&v| if v.is_finite() { (v.clamp(0.0, 1.0) * 255.0).round() as u8 } else { 0 }).collect();
    let image = RgbImage::from_raw(size.width, size.height, bytes)
        .ok_or_else(|| FormatError::invalid(path, "RGB buffer does not fill the image"))?;
    crate::write_png(path, &image.into())
}

/// Reads an image as interleaved RGB in `[0, 1]`.
pub fn read_rgb_png(path: &Path) -> Result<(ImageSize, Vec<f32>), FormatError> {
    let bytes = crate::read_file(path)?;
    let image =
        image::load_from_memory(&bytes).map_err(|e| FormatError::malformed(path, "an image", e.to_string()))?.to_rgb8();
    let size = ImageSize::new(image.width(), image.height()).map_err(|e| FormatError::invalid(path, e.to_string()))?;
    Ok((size, image.as_raw().iter().map(|&v| v as f32 / 255.0).collect()))
}
