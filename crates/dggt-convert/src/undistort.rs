//! Lens undistortion at conversion: a camera image recorded through a lens with distortion, resampled to the
//! ideal pinhole camera of the same intrinsics and size, so that the export's pinhole intrinsics, its masks and
//! the lidar's returns agree with its pixels everywhere in the image, not only near the centre.
//!
//! Argoverse 2's ring cameras have strong barrel distortion (`k1` about -0.28): at a 2048-pixel image's edge the
//! pinhole model misplaces a point by about 100 pixels. drivestudio's export drops the coefficients and keeps the
//! recorded images ([`Lens::AsRecorded`]); [`Lens::Undistorted`] resamples them.
//!
//! Conventions as in [`crate::camera`]: pixel `(col, row)` covers `[col, col + 1) x [row, row + 1)`, so its
//! centre is at `(col + 0.5, row + 0.5)`. Each output pixel reads the recorded image bilinearly at the distorted
//! position of its centre; a position outside the recorded image reads black.

use dggt_geom::glam::DVec2;
use image::{Rgb, RgbImage};

use crate::camera::EgoCamera;

/// What a conversion does with a camera's lens distortion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Lens {
    /// Images resampled to the pinhole model; the export's intrinsics hold no distortion and mean it.
    #[default]
    Undistorted,
    /// The recorded images, the distortion dropped from the intrinsics (drivestudio's Argoverse 2 export).
    AsRecorded,
}

impl Lens {
    /// `undistorted` or `as-recorded`, as a done marker records it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Undistorted => "undistorted",
            Self::AsRecorded => "as-recorded",
        }
    }
}

/// Where each pixel of the pinhole image reads the recorded one: built once per camera, applied to each frame.
#[derive(Debug, Clone)]
pub struct Undistortion {
    width: u32,
    height: u32,
    /// Per output pixel (row-major), the recorded image's position of its centre, in pixel-index coordinates
    /// (pixel `(col, row)`'s centre at `(col, row)`).
    sources: Vec<[f32; 2]>,
}

impl Undistortion {
    /// The resampling of `camera`'s recorded images (its intrinsics, size and distortion) to its pinhole model.
    pub fn of(camera: &EgoCamera) -> Self {
        let (width, height) = (camera.size.width, camera.size.height);
        let k = &camera.intrinsics;
        let sources = (0..height)
            .flat_map(|row| (0..width).map(move |col| (col, row)))
            .map(|(col, row)| {
                let ideal = DVec2::new((col as f64 + 0.5 - k.cx) / k.fx, (row as f64 + 0.5 - k.cy) / k.fy);
                let distorted = camera.distortion.apply(ideal);
                [(k.fx * distorted.x + k.cx - 0.5) as f32, (k.fy * distorted.y + k.cy - 0.5) as f32]
            })
            .collect();
        Self { width, height, sources }
    }

    /// The pinhole image of a recorded one; `None` when `recorded` is not of the camera's size.
    pub fn apply(&self, recorded: &RgbImage) -> Option<RgbImage> {
        if recorded.dimensions() != (self.width, self.height) {
            return None;
        }
        let mut out = RgbImage::new(self.width, self.height);
        for (pixel, source) in out.pixels_mut().zip(&self.sources) {
            *pixel = bilinear(recorded, source[0], source[1]);
        }
        Some(out)
    }
}

/// `image` read at `(x, y)` in pixel-index coordinates, bilinearly; black outside the image (a pixel's centre
/// half a pixel beyond the border still reads the border pixel's share).
fn bilinear(image: &RgbImage, x: f32, y: f32) -> Rgb<u8> {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (width, height) = (image.width() as i64, image.height() as i64);
    let read = |col: i64, row: i64| -> [f32; 3] {
        if col < 0 || row < 0 || col >= width || row >= height {
            return [0.0; 3];
        }
        image.get_pixel(col as u32, row as u32).0.map(f32::from)
    };
    let (c0, r0) = (x0 as i64, y0 as i64);
    let corners = [(c0, r0, (1.0 - fx) * (1.0 - fy)), (c0 + 1, r0, fx * (1.0 - fy)), (c0, r0 + 1, (1.0 - fx) * fy)];
    let mut sum = read(c0 + 1, r0 + 1).map(|v| v * fx * fy);
    for (col, row, weight) in corners {
        let value = read(col, row);
        for (s, v) in sum.iter_mut().zip(value) {
            *s += v * weight;
        }
    }
    Rgb(sum.map(|v| v.round().clamp(0.0, 255.0) as u8))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Distortion;
    use dggt_geom::glam::DVec3;
    use dggt_geom::{ImageSize, PinholeIntrinsics, Rigid};

    /// A 200 x 150 camera looking along the ego's x axis, with `distortion`.
    fn camera(distortion: Distortion) -> EgoCamera {
        EgoCamera {
            intrinsics: PinholeIntrinsics::new(120.0, 120.0, 100.0, 75.0).unwrap(),
            distortion,
            camera_from_ego: dggt_geom::axes::ego_from_opencv_camera(&Rigid::IDENTITY).inverse(),
            size: ImageSize::new(200, 150).unwrap(),
        }
    }

    /// White 3 x 3 dots on black where `camera` (with its distortion) sees each of `points`.
    fn dots(camera: &EgoCamera, points: &[DVec3]) -> RgbImage {
        let mut image = RgbImage::new(200, 150);
        for &p in points {
            let pixel = camera.project_inside(p).unwrap();
            let (col, row) = (pixel.x as i64, pixel.y as i64);
            for (dc, dr) in (-1..=1).flat_map(|dc| (-1..=1).map(move |dr| (dc, dr))) {
                image.put_pixel((col + dc) as u32, (row + dr) as u32, Rgb([255; 3]));
            }
        }
        image
    }

    /// The brightness-weighted centre of the pixels within 6 px of `around`.
    fn centroid(image: &RgbImage, around: DVec2) -> DVec2 {
        let (mut sum, mut weight) = (DVec2::ZERO, 0.0);
        for (col, row, p) in image.enumerate_pixels() {
            let centre = DVec2::new(col as f64 + 0.5, row as f64 + 0.5);
            if (centre - around).length() <= 6.0 {
                sum += centre * f64::from(p.0[0]);
                weight += f64::from(p.0[0]);
            }
        }
        sum / weight
    }

    #[test]
    fn a_barrel_distorted_image_resampled_puts_each_point_where_the_pinhole_projects_it() {
        let barrel = camera(Distortion { k1: -0.28, k2: -0.03, k3: 0.1, ..Default::default() });
        let pinhole = camera(Distortion::default());
        // Three points towards the corners, where the lens moves them most, one on the axis and one between.
        let points: Vec<DVec3> =
            [(10.0, 6.0, 4.0), (10.0, -6.5, -4.0), (10.0, 5.5, -4.5), (10.0, 0.0, 0.0), (10.0, -3.0, 2.0)]
                .map(|(x, y, z)| DVec3::new(x, y, z))
                .to_vec();
        let recorded = dots(&barrel, &points);
        let undistorted = Undistortion::of(&barrel).apply(&recorded).unwrap();
        for &p in &points {
            let (expected, recorded_at) = (pinhole.project(p).unwrap(), barrel.project(p).unwrap());
            // The recorded dot is centred on the pixel the point falls in (up to half a pixel off), which the
            // resampling stretches by up to a third towards the corners.
            let found = centroid(&undistorted, expected);
            assert!((found - expected).length() < 1.0, "{p}: dot at {found}, pinhole projection {expected}");
            if p.y.abs() > 5.0 {
                assert!((recorded_at - expected).length() > 4.0, "the lens moved {p} visibly: {recorded_at}");
            }
        }
        assert!(Undistortion::of(&barrel).apply(&RgbImage::new(10, 10)).is_none(), "a wrong size is refused");
    }

    #[test]
    fn without_distortion_the_image_is_unchanged() {
        let image = RgbImage::from_fn(200, 150, |x, y| Rgb([(x % 256) as u8, (y % 256) as u8, ((x * y) % 251) as u8]));
        assert_eq!(Undistortion::of(&camera(Distortion::default())).apply(&image).unwrap(), image);
    }
}
