//! Depth maps: float32 `.npy` (shape `[H, W]`, C order) and 16-bit grayscale PNG with its scale in a JSON file
//! beside it (`NAME.png` + `NAME.json`).
//!
//! Convention: z-depth along the optical axis, in the reconstruction's units (DGGT's depth is up to scale,
//! hence the stored scale). In the PNG, `depth = value * scale`; `0` means no depth (non-finite or
//! non-positive input). Values are rounded, so a depth is recovered within `scale / 2`.

use std::path::{Path, PathBuf};

use dggt_geom::ImageSize;
use image::{ImageBuffer, Luma};
use serde::{Deserialize, Serialize};

use crate::FormatError;

/// Writes `depth` (`size.area()` values, row-major) as a float32 `.npy` of shape `[H, W]`.
pub fn write_depth_npy(path: &Path, size: ImageSize, depth: &[f32]) -> Result<(), FormatError> {
    use npyz::WriterBuilder;
    check_len(path, size, depth.len())?;
    let mut bytes = Vec::new();
    let mut writer = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&[size.height as u64, size.width as u64])
        .writer(&mut bytes)
        .begin_nd()
        .map_err(|e| FormatError::io(path, e))?;
    writer.extend(depth.iter().copied()).map_err(|e| FormatError::io(path, e))?;
    writer.finish().map_err(|e| FormatError::io(path, e))?;
    crate::write_file(path, &bytes)
}

/// Reads a float32 `[H, W]` `.npy`.
pub fn read_depth_npy(path: &Path) -> Result<(ImageSize, Vec<f32>), FormatError> {
    let bytes = crate::read_file(path)?;
    let file =
        npyz::NpyFile::new(&bytes[..]).map_err(|e| FormatError::malformed(path, "a .npy file", e.to_string()))?;
    if file.dtype() != <f32 as npyz::AutoSerialize>::default_dtype() || file.order() != npyz::Order::C {
        return Err(FormatError::malformed(path, "C-order little-endian float32", file.dtype().descr()));
    }
    let shape = file.shape().to_vec();
    let [h, w] = shape[..] else {
        return Err(FormatError::malformed(path, "a 2-D array [H, W]", format!("shape {shape:?}")));
    };
    let size = ImageSize::new(w as u32, h as u32).map_err(|e| FormatError::invalid(path, e.to_string()))?;
    let data: Vec<f32> =
        file.into_vec().map_err(|e| FormatError::malformed(path, "complete float32 data", e.to_string()))?;
    check_len(path, size, data.len())?;
    Ok((size, data))
}

/// The JSON stored beside a 16-bit depth PNG.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DepthScale {
    /// `depth = value * scale`.
    pub scale: f64,
    /// The PNG value that means "no depth".
    pub invalid_value: u16,
    /// What the depth measures.
    pub meaning: String,
}

/// The scale that maps `max_depth` to the largest 16-bit value (1 when there is no positive depth).
pub fn scale_for(max_depth: f32) -> f64 {
    if max_depth.is_finite() && max_depth > 0.0 { max_depth as f64 / u16::MAX as f64 } else { 1.0 }
}

/// The JSON path beside a PNG path: same stem, `.json`.
pub fn scale_path(png: &Path) -> PathBuf {
    png.with_extension("json")
}

/// Writes `depth` as a 16-bit PNG at `path` with `scale` (see [`scale_for`]) and its JSON beside it. Depths
/// beyond `65535 * scale` saturate.
pub fn write_depth_png16(path: &Path, size: ImageSize, depth: &[f32], scale: f64) -> Result<(), FormatError> {
    check_len(path, size, depth.len())?;
    if !(scale.is_finite() && scale > 0.0) {
        return Err(FormatError::invalid(path, format!("depth scale {scale} is not positive")));
    }
    let values: Vec<u16> =
        depth
            .iter()
            .map(|&d| {
                if d.is_finite() && d > 0.0 { (d as f64 / scale).round().clamp(1.0, u16::MAX as f64) as u16 } else { 0 }
            })
            .collect();
    let image: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_raw(size.width, size.height, values)
        .ok_or_else(|| FormatError::invalid(path, "depth buffer does not fill the image"))?;
    let mut bytes = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|e| FormatError::invalid(path, format!("encoding PNG: {e}")))?;
    crate::write_file(path, &bytes.into_inner())?;
    let meta = DepthScale {
        scale,
        invalid_value: 0,
        meaning: "z-depth along the optical axis = value * scale (reconstruction units, up to scale)".into(),
    };
    let json_path = scale_path(path);
    let text = serde_json::to_string_pretty(&meta).map_err(|e| FormatError::invalid(&json_path, e.to_string()))?;
    crate::write_file(&json_path, text.as_bytes())
}

/// Reads a 16-bit depth PNG and its JSON; invalid pixels come back as 0.
pub fn read_depth_png16(path: &Path) -> Result<(ImageSize, Vec<f32>, DepthScale), FormatError> {
    let json_path = scale_path(path);
    let meta: DepthScale = serde_json::from_slice(&crate::read_file(&json_path)?)
        .map_err(|e| FormatError::malformed(&json_path, "a depth-scale JSON", e.to_string()))?;
    let bytes = crate::read_file(path)?;
    let image = image::load_from_memory(&bytes).map_err(|e| FormatError::malformed(path, "a PNG", e.to_string()))?;
    let image::DynamicImage::ImageLuma16(gray) = image else {
        return Err(FormatError::malformed(path, "a 16-bit grayscale PNG", format!("{:?}", image.color())));
    };
    let size = ImageSize::new(gray.width(), gray.height()).map_err(|e| FormatError::invalid(path, e.to_string()))?;
    let depth = gray
        .as_raw()
        .iter()
        .map(|&v| if v == meta.invalid_value { 0.0 } else { (v as f64 * meta.scale) as f32 })
        .collect();
    Ok((size, depth, meta))
}

fn check_len(path: &Path, size: ImageSize, len: usize) -> Result<(), FormatError> {
    if len != size.area() {
        return Err(FormatError::invalid(path, format!("{len} depth values for a {size} image")));
    }
    Ok(())
}
