//! The release's image preprocessing: resize to a target width with the height rounded to a multiple of the
//! patch size, then centre-crop the height to the width when taller. Masks follow the same geometry and are
//! binarised; intrinsics are adjusted to match.
//!
//! Resampling is bicubic (Catmull-Rom, `a = -0.5`) with the kernel widened when downscaling, as PIL's
//! `BICUBIC` resize that the release uses ([`dggt_resize`]).

use dggt_geom::{ImageSize, PinholeIntrinsics};
use dggt_resize::{Pixels, resize};
use image::{GrayImage, RgbImage};
use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};

/// Preprocessing settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preprocess {
    /// Output width in pixels; a multiple of `patch_size` (518 for the released model).
    pub target_width: u32,
    /// The network's patch size (14).
    pub patch_size: u32,
    /// Centre-crop the height to the width when the resized image is taller than wide.
    pub crop_to_square: bool,
}

impl Default for Preprocess {
    fn default() -> Self {
        Self { target_width: 518, patch_size: 14, crop_to_square: true }
    }
}

/// The geometry of preprocessing one image size: resize, then crop rows from the top.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PreprocessPlan {
    pub original: ImageSize,
    pub resized: ImageSize,
    /// Rows removed from the top of the resized image.
    pub crop_top: u32,
    pub output: ImageSize,
}

/// An RGB image ready for the network: planar `[3, H, W]`, values in `[0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarImage {
    pub size: ImageSize,
    pub data: Vec<f32>,
}

impl PlanarImage {
    /// The pixels interleaved, `[H, W, 3]` (what image files and the metrics take).
    pub fn interleaved(&self) -> Vec<f32> {
        let plane = self.size.area();
        (0..plane).flat_map(|i| [self.data[i], self.data[plane + i], self.data[2 * plane + i]]).collect()
    }
}

/// A binary mask `[H, W]`: 1 where the property holds (sky, dynamic), else 0.
#[derive(Debug, Clone, PartialEq)]
pub struct BinaryMask {
    pub size: ImageSize,
    pub data: Vec<u8>,
}

impl BinaryMask {
    /// Fraction of pixels set.
    pub fn coverage(&self) -> f64 {
        self.data.iter().map(|&v| v as usize).sum::<usize>() as f64 / self.data.len().max(1) as f64
    }
}

impl Preprocess {
    /// Checks the settings.
    pub fn validate(&self) -> Result<()> {
        if self.patch_size == 0 || self.target_width == 0 || !self.target_width.is_multiple_of(self.patch_size) {
            return Err(DataError::Config(format!(
                "target_width {} must be a positive multiple of patch_size {}",
                self.target_width, self.patch_size
            )));
        }
        Ok(())
    }

    /// The resize and crop applied to images of `original` size.
    pub fn plan(&self, original: ImageSize) -> Result<PreprocessPlan> {
        self.validate()?;
        let width = self.target_width;
        let patch = self.patch_size as f64;
        let scaled_height = original.height as f64 * width as f64 / original.width as f64;
        // Python's round(), which the release uses, rounds halves to even.
        let height = ((scaled_height / patch).round_ties_even() * patch) as u32;
        if height == 0 {
            return Err(DataError::Config(format!(
                "an image of {original} resized to width {width} is less than one patch ({}) tall",
                self.patch_size
            )));
        }
        let resized = ImageSize { width, height };
        let (crop_top, output) = if self.crop_to_square && height > width {
            ((height - width) / 2, ImageSize { width, height: width })
        } else {
            (0, resized)
        };
        Ok(PreprocessPlan { original, resized, crop_top, output })
    }
}

impl PreprocessPlan {
    /// Intrinsics of the output image, given those of the original.
    pub fn intrinsics(&self, original: &PinholeIntrinsics) -> PinholeIntrinsics {
        original
            .scaled(
                self.resized.width as f64 / self.original.width as f64,
                self.resized.height as f64 / self.original.height as f64,
            )
            .cropped(0.0, self.crop_top as f64)
    }

    fn check_input(&self, what: &str, size: ImageSize) -> Result<()> {
        if size != self.original {
            return Err(DataError::Config(format!(
                "{what} of {size} given to a preprocessing plan for {}",
                self.original
            )));
        }
        Ok(())
    }

    /// Resizes, crops and converts an RGB image.
    pub fn image(&self, image: &RgbImage) -> Result<PlanarImage> {
        self.check_input("an image", ImageSize { width: image.width(), height: image.height() })?;
        let resized = self.resize(image.as_raw(), Pixels::Rgb)?;
        let (w, h) = (self.output.width as usize, self.output.height as usize);
        let plane = w * h;
        let mut data = vec![0f32; 3 * plane];
        let start = self.crop_top as usize * w * 3;
        for (i, rgb) in resized[start..start + plane * 3].chunks_exact(3).enumerate() {
            for c in 0..3 {
                data[c * plane + i] = rgb[c] as f32 / 255.0;
            }
        }
        Ok(PlanarImage { size: self.output, data })
    }

    /// Resizes and crops a mask with the image's filter, then binarises at one half.
    pub fn mask(&self, mask: &GrayImage) -> Result<BinaryMask> {
        self.check_input("a mask", ImageSize { width: mask.width(), height: mask.height() })?;
        let resized = self.resize(mask.as_raw(), Pixels::Gray)?;
        let w = self.output.width as usize;
        let start = self.crop_top as usize * w;
        let data = resized[start..start + self.output.area()].iter().map(|&v| u8::from(v >= 128)).collect();
        Ok(BinaryMask { size: self.output, data })
    }

    fn resize(&self, pixels: &[u8], layout: Pixels) -> Result<Vec<u8>> {
        if self.resized == self.original {
            return Ok(pixels.to_vec());
        }
        let (from, to) = (self.original, self.resized);
        resize(pixels, layout, (from.width, from.height), (to.width, to.height))
            .map_err(|e| DataError::Config(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_planar_image_interleaves_its_channels_per_pixel() {
        let image = PlanarImage { size: ImageSize::new(2, 1).unwrap(), data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0] };
        assert_eq!(image.interleaved(), [1.0, 3.0, 5.0, 2.0, 4.0, 6.0]);
    }

    fn size(width: u32, height: u32) -> ImageSize {
        ImageSize::new(width, height).unwrap()
    }

    #[test]
    fn release_sizes() {
        let p = Preprocess::default();
        assert_eq!(p.plan(size(1920, 1280)).unwrap().output, size(518, 350));
        assert_eq!(p.plan(size(1920, 886)).unwrap().output, size(518, 238));
        let portrait = p.plan(size(1550, 2048)).unwrap();
        assert_eq!(portrait.resized, size(518, 686));
        assert_eq!((portrait.crop_top, portrait.output), (84, size(518, 518)));
        assert!(Preprocess { target_width: 500, ..p }.plan(size(10, 10)).is_err());
        // Halves round to even, as Python's round(): 70 * 70 / 140 / 14 = 2.5 patches -> 2.
        let tiny = Preprocess { target_width: 70, patch_size: 14, crop_to_square: true };
        assert_eq!(tiny.plan(size(140, 70)).unwrap().output, size(70, 28));
    }

    #[test]
    fn intrinsics_follow_the_pixels() {
        // A bright dot at a known 3D direction must stay where the adjusted intrinsics project it.
        let original = size(320, 400);
        let k = PinholeIntrinsics::new(300.0, 300.0, 160.0, 200.0).unwrap();
        let plan = Preprocess { target_width: 70, patch_size: 14, crop_to_square: true }.plan(original).unwrap();
        let point = dggt_geom::glam::DVec3::new(0.05, -0.08, 1.0);
        let uv = k.project(point).unwrap();
        let mut image = RgbImage::new(320, 400);
        for y in 0..400 {
            for x in 0..320 {
                let d = (x as f64 + 0.5 - uv.x).hypot(y as f64 + 0.5 - uv.y);
                let v = (255.0 * (-d * d / 200.0).exp()) as u8;
                image.put_pixel(x, y, image::Rgb([v, v, v]));
            }
        }
        let out = plan.image(&image).unwrap();
        let expected = plan.intrinsics(&k).project(point).unwrap();
        let (w, h) = (out.size.width as usize, out.size.height as usize);
        let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let v = out.data[y * w + x] as f64;
                sx += v * (x as f64 + 0.5);
                sy += v * (y as f64 + 0.5);
                sw += v;
            }
        }
        let centroid = (sx / sw, sy / sw);
        assert!(
            (centroid.0 - expected.x).abs() < 0.3 && (centroid.1 - expected.y).abs() < 0.3,
            "{centroid:?} vs {expected:?}"
        );
    }

    #[test]
    fn masks_are_binary_and_aligned() {
        let original = size(140, 98);
        let plan = Preprocess { target_width: 70, patch_size: 14, crop_to_square: true }.plan(original).unwrap();
        let mask = GrayImage::from_fn(140, 98, |x, _| image::Luma([if x < 70 { 255 } else { 0 }]));
        let out = plan.mask(&mask).unwrap();
        assert!(out.data.iter().all(|&v| v <= 1));
        assert!((out.coverage() - 0.5).abs() < 1e-9, "{}", out.coverage());
        assert!(plan.mask(&GrayImage::new(10, 10)).is_err());
    }
}
