//! A calibrated camera on the ego vehicle, projecting ego-frame points to pixels with OpenCV's lens model.
//!
//! Conventions: the camera frame has OpenCV axes (x right, y down, z forward); `camera_from_ego` maps ego points
//! (forward-left-up) into it; pixel coordinates span `[0, W] x [0, H]`, so pixel `(col, row)` covers
//! `[col, col + 1) x [row, row + 1)`. Distortion is OpenCV's `k1 k2 p1 p2 k3` (zero for an ideal pinhole).

use dggt_geom::glam::{DVec2, DVec3};
use dggt_geom::{Camera, Ego, ImageSize, PinholeIntrinsics, Rigid};

/// OpenCV distortion coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

impl Distortion {
    /// Maps undistorted normalised coordinates to distorted ones.
    pub(crate) fn apply(&self, xy: DVec2) -> DVec2 {
        let (x, y) = (xy.x, xy.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        DVec2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }
}

/// A camera as the converters project into it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgoCamera {
    pub intrinsics: PinholeIntrinsics,
    pub distortion: Distortion,
    pub camera_from_ego: Rigid<Camera, Ego>,
    pub size: ImageSize,
}

impl EgoCamera {
    /// Continuous pixel coordinates of an ego-frame point, or `None` when it is not in front of the camera.
    pub fn project(&self, point_in_ego: DVec3) -> Option<DVec2> {
        let p = self.camera_from_ego.transform_point(point_in_ego);
        if p.z <= 0.0 {
            return None;
        }
        let distorted = self.distortion.apply(DVec2::new(p.x / p.z, p.y / p.z));
        let k = &self.intrinsics;
        Some(DVec2::new(k.fx * distorted.x + k.cx, k.fy * distorted.y + k.cy))
    }

    /// Pixel coordinates of a camera-frame point in front of the camera, for outlines that reach beyond the
    /// image: the lens model is applied at most out to the image corners' radius (beyond, OpenCV's polynomial
    /// can fold back towards the centre), and the point is carried on from there along its own ray direction.
    pub fn project_camera_point(&self, point_in_camera: DVec3) -> Option<DVec2> {
        if point_in_camera.z <= 0.0 {
            return None;
        }
        let ideal = DVec2::new(point_in_camera.x / point_in_camera.z, point_in_camera.y / point_in_camera.z);
        let k = &self.intrinsics;
        let corner = DVec2::new(
            (k.cx.abs()).max((self.size.width as f64 - k.cx).abs()) / k.fx,
            (k.cy.abs()).max((self.size.height as f64 - k.cy).abs()) / k.fy,
        );
        let limit = corner.length();
        let radius = ideal.length();
        let distorted = if radius <= limit {
            self.distortion.apply(ideal)
        } else {
            self.distortion.apply(ideal * (limit / radius)) * (radius / limit)
        };
        Some(DVec2::new(k.fx * distorted.x + k.cx, k.fy * distorted.y + k.cy))
    }

    /// [`Self::project`], kept only when the pixel lies inside the image.
    pub fn project_inside(&self, point_in_ego: DVec3) -> Option<DVec2> {
        let pixel = self.project(point_in_ego)?;
        let inside =
            pixel.x >= 0.0 && pixel.y >= 0.0 && pixel.x < self.size.width as f64 && pixel.y < self.size.height as f64;
        inside.then_some(pixel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn forward_camera(distortion: Distortion) -> EgoCamera {
        let ego_from_camera = dggt_geom::axes::ego_from_opencv_camera(&Rigid::IDENTITY);
        EgoCamera {
            intrinsics: PinholeIntrinsics::new(100.0, 100.0, 50.0, 40.0).unwrap(),
            distortion,
            camera_from_ego: ego_from_camera.inverse(),
            size: ImageSize::new(100, 80).unwrap(),
        }
    }

    #[test]
    fn a_forward_camera_sees_left_on_the_left_and_up_at_the_top() {
        let camera = forward_camera(Distortion::default());
        let pixel = camera.project(DVec3::new(10.0, 1.0, 0.5)).unwrap();
        assert!(pixel.abs_diff_eq(DVec2::new(40.0, 35.0), 1e-12), "{pixel}");
        assert!(camera.project(DVec3::new(-1.0, 0.0, 0.0)).is_none(), "behind the camera");
        assert!(camera.project_inside(DVec3::new(10.0, 10.0, 0.0)).is_none(), "left of the image");
    }

    #[test]
    fn barrel_distortion_pulls_points_towards_the_centre_and_spares_the_axis() {
        let ideal = forward_camera(Distortion::default());
        let barrel = forward_camera(Distortion { k1: -0.2, ..Default::default() });
        let on_axis = DVec3::new(5.0, 0.0, 0.0);
        assert_eq!(ideal.project(on_axis), barrel.project(on_axis));
        let off_axis = DVec3::new(5.0, 2.0, -1.0);
        let (u0, u1) = (ideal.project(off_axis).unwrap(), barrel.project(off_axis).unwrap());
        let centre = DVec2::new(50.0, 40.0);
        // r² = 0.4² + 0.2² = 0.2, so the offset from the centre shrinks by 1 - 0.2 · 0.2 = 0.96.
        assert!(((u1 - centre) - (u0 - centre) * 0.96).length() < 1e-12, "{u0} {u1}");
    }
}
