//! The moving objects between the inputs drawn every way the reconstruction can draw them, side by side.
//!
//! At a view between the inputs the dynamic Gaussians of the bracketing inputs must be carried to the view's
//! time, and how is a choice ([`dggt_scene::DynamicBlend`] and [`dggt_scene::DynamicMotion`]). Each
//! [`ImageSource`] is one such choice; every one the scene supports is rendered at the same view and scored by
//! its PSNR over the export's dynamic mask (the moving objects' pixels), so the sources compare on the same
//! pixels. With [`CropImages::Write`] the mask's neighbourhood is also written as one strip per view: the truth,
//! then each source in [`ImageSource::ALL`]'s order.

use std::path::Path;

use dggt_data::BinaryMask;
use dggt_geom::ImageSize;
use dggt_scene::{AssemblySettings, DynamicBlend, DynamicMotion, PixelGaussians, Scene4d, TargetView, render_target};

use crate::error::EvalError;

/// One way of carrying the inputs' dynamic Gaussians to a time between them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageSource {
    /// The nearest input's dynamic Gaussians where they were predicted (the release).
    Held,
    /// Both bracketing inputs' dynamic Gaussians where they were predicted, opacities weighted by time.
    CrossFade,
    /// Moved by the predicted velocities (the reconstruction's blend).
    Velocity,
    /// Moved rigidly along their objects' trajectories (the reconstruction's blend).
    Instances,
    /// Moved along the flow head's learnt flow (the reconstruction's blend).
    Learnt,
}

impl ImageSource {
    pub const ALL: [Self; 5] = [Self::Held, Self::CrossFade, Self::Velocity, Self::Instances, Self::Learnt];

    /// The name in reports and in the crops' legend.
    pub fn name(self) -> &'static str {
        match self {
            Self::Held => "held",
            Self::CrossFade => "cross-fade",
            Self::Velocity => "velocity",
            Self::Instances => "instances",
            Self::Learnt => "learnt",
        }
    }

    /// The assembly of `base` with this source's blend and motion.
    pub fn assembly(self, base: &AssemblySettings) -> AssemblySettings {
        let (dynamic_blend, dynamic_motion) = match self {
            Self::Held => (DynamicBlend::Nearest, DynamicMotion::Held),
            Self::CrossFade => (DynamicBlend::CrossFade, DynamicMotion::Held),
            Self::Velocity => (base.dynamic_blend, DynamicMotion::Velocity),
            Self::Instances => (base.dynamic_blend, DynamicMotion::Instances),
            Self::Learnt => (base.dynamic_blend, DynamicMotion::Learnt),
        };
        AssemblySettings { dynamic_blend, dynamic_motion, ..*base }
    }

    /// The sources `pixels` can be drawn with: held and cross-faded with a dynamic head, velocities when
    /// predicted, instances when found; nothing without a dynamic head (nothing moves).
    pub fn available(pixels: &PixelGaussians) -> Vec<Self> {
        if pixels.dynamic_logit.is_none() {
            return Vec::new();
        }
        Self::ALL
            .into_iter()
            .filter(|source| match source {
                Self::Held | Self::CrossFade => true,
                Self::Velocity => pixels.host_velocity().is_some(),
                Self::Instances => pixels.instances().is_some(),
                Self::Learnt => pixels.learnt().is_some(),
            })
            .collect()
    }
}

/// Whether `dggt eval` writes crops of the moving objects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CropImages {
    #[default]
    Skip,
    /// `crops/<scene>/f<frame>_c<camera>.png` for every view between the inputs with a dynamic mask.
    Write,
}

/// `target` rendered under each of `sources`, colours interleaved `[H, W, 3]` and clamped to `[0, 1]`; the
/// source that draws as the scene's own assembly takes `own` (the view's render already made) instead.
pub(crate) fn render_sources(
    scene: &Scene4d,
    target: &TargetView,
    sources: &[ImageSource],
    own: &[f32],
) -> Result<Vec<(ImageSource, Vec<f32>)>, EvalError> {
    sources
        .iter()
        .map(|&source| {
            let assembly = source.assembly(&scene.assembly);
            if assembly == scene.assembly {
                return Ok((source, own.to_vec()));
            }
            let render = render_target(&scene.pixels, scene.sky.as_ref(), target, &assembly)?;
            Ok((source, clamped_colours(render.rgb)?))
        })
        .collect()
}

/// A render's colours read back, interleaved `[H, W, 3]`, clamped to `[0, 1]`.
pub(crate) fn clamped_colours(rgb: burn::tensor::Tensor<3>) -> Result<Vec<f32>, EvalError> {
    let rgb = dggt_model::host::host_f32(rgb, "rendered colours")?;
    Ok(rgb.into_iter().map(|v| v.clamp(0.0, 1.0)).collect())
}

/// A pixel rectangle, ends exclusive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelBox {
    pub columns: (usize, usize),
    pub rows: (usize, usize),
}

/// The rectangle around `mask`'s set pixels, grown by a fifth of its size on each side (at least 4 pixels) and
/// kept inside the image; `None` for an empty mask.
pub fn crop_box(mask: &BinaryMask) -> Option<PixelBox> {
    let (width, height) = (mask.size.width as usize, mask.size.height as usize);
    let set = mask.data.iter().enumerate().filter(|&(_, &v)| v > 0).map(|(i, _)| (i % width, i / width));
    let (mut left, mut top, mut right, mut bottom) = (usize::MAX, usize::MAX, 0, 0);
    for (column, row) in set {
        (left, top, right, bottom) = (left.min(column), top.min(row), right.max(column + 1), bottom.max(row + 1));
    }
    if left == usize::MAX {
        return None;
    }
    let grow = |low: usize, high: usize, limit: usize| {
        let margin = ((high - low) / 5).max(4);
        (low.saturating_sub(margin), (high + margin).min(limit))
    };
    Some(PixelBox { columns: grow(left, right, width), rows: grow(top, bottom, height) })
}

/// Height in pixels the crops are enlarged to (at least; by a whole factor, nearest neighbour).
const CROP_HEIGHT: usize = 96;
/// White columns between the crops of a strip.
const GAP: usize = 2;

/// Writes the strip of `images` (interleaved `[H, W, 3]` of `size`: the truth first, then the sources) cut to
/// `area`, each enlarged by a whole factor to at least [`CROP_HEIGHT`] rows.
pub(crate) fn write_crop_strip(
    path: &Path,
    size: ImageSize,
    area: PixelBox,
    images: &[&[f32]],
) -> Result<(), EvalError> {
    let width = size.width as usize;
    let (crop_w, crop_h) = (area.columns.1 - area.columns.0, area.rows.1 - area.rows.0);
    let factor = CROP_HEIGHT.div_ceil(crop_h).max(1);
    let (tile_w, tile_h) = (crop_w * factor, crop_h * factor);
    let strip_w = images.len() * tile_w + images.len().saturating_sub(1) * GAP;
    let mut strip = vec![1.0f32; strip_w * tile_h * 3];
    for (k, image) in images.iter().enumerate() {
        let origin = k * (tile_w + GAP);
        for y in 0..tile_h {
            for x in 0..tile_w {
                let source = ((area.rows.0 + y / factor) * width + area.columns.0 + x / factor) * 3;
                let target = (y * strip_w + origin + x) * 3;
                strip[target..target + 3].copy_from_slice(&image[source..source + 3]);
            }
        }
    }
    let strip_size = ImageSize { width: strip_w as u32, height: tile_h as u32 };
    dggt_formats::images::write_rgb_png(path, strip_size, &strip)
        .map_err(|source| EvalError::Crops { path: path.to_path_buf(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(width: u32, height: u32, set: &[(usize, usize)]) -> BinaryMask {
        let mut data = vec![0u8; (width * height) as usize];
        for &(column, row) in set {
            data[row * width as usize + column] = 1;
        }
        BinaryMask { size: ImageSize { width, height }, data }
    }

    #[test]
    fn the_crop_box_grows_around_the_mask_and_stays_inside_the_image() {
        assert_eq!(crop_box(&mask(40, 30, &[])), None);
        let area = crop_box(&mask(40, 30, &[(10, 12), (29, 13)])).unwrap();
        // 20 columns wide: a fifth is 4; one row high: at least 4.
        assert_eq!(area, PixelBox { columns: (6, 34), rows: (8, 18) });
        let corner = crop_box(&mask(40, 30, &[(0, 0), (39, 29)])).unwrap();
        assert_eq!(corner, PixelBox { columns: (0, 40), rows: (0, 30) });
    }

    #[test]
    fn each_source_draws_its_own_blend_and_motion() {
        let base = AssemblySettings { dynamic_blend: DynamicBlend::Nearest, ..AssemblySettings::default() };
        let pairs: Vec<_> = ImageSource::ALL
            .iter()
            .map(|s| {
                let a = s.assembly(&base);
                (a.dynamic_blend, a.dynamic_motion)
            })
            .collect();
        assert_eq!(
            pairs,
            [
                (DynamicBlend::Nearest, DynamicMotion::Held),
                (DynamicBlend::CrossFade, DynamicMotion::Held),
                (DynamicBlend::Nearest, DynamicMotion::Velocity),
                (DynamicBlend::Nearest, DynamicMotion::Instances),
                (DynamicBlend::Nearest, DynamicMotion::Learnt),
            ]
        );
    }

    #[test]
    fn a_strip_holds_each_crop_enlarged_side_by_side() {
        let size = ImageSize { width: 4, height: 3 };
        let truth: Vec<f32> = (0..36).map(|i| i as f32 / 36.0).collect();
        let other = vec![0.25f32; 36];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("strip.png");
        let area = PixelBox { columns: (1, 3), rows: (1, 2) };
        write_crop_strip(&path, size, area, &[&truth, &other]).unwrap();
        let (strip_size, strip) = dggt_formats::images::read_rgb_png(&path).unwrap();
        // One row enlarged 96 times, two columns each; a gap of two between the two crops.
        assert_eq!((strip_size.width, strip_size.height), (2 * 192 + GAP as u32, 96));
        let at = |x: usize, y: usize| &strip[(y * strip_size.width as usize + x) * 3..][..3];
        let expected = |column: usize| -> Vec<f32> { (0..3).map(|c| truth[(4 + column) * 3 + c]).collect() };
        for (x, column) in [(0, 1), (95, 1), (96, 2), (191, 2)] {
            for (got, want) in at(x, 50).iter().zip(expected(column)) {
                assert!((got - want).abs() < 1.0 / 255.0, "x {x}: {got} vs {want}");
            }
        }
        assert_eq!(at(192, 0), [1.0, 1.0, 1.0]);
        assert!(at(194, 10).iter().all(|&v| (v - 0.25).abs() < 1.0 / 255.0));
    }
}
