//! Ray-cast point maps of two cars seen by one forward-looking pinhole camera at the origin (OpenCV axes): the
//! car ahead turning left through a curve, and an oncoming car driving straight, each at 8 m per unit of time.
//! Shared by the tests and the benchmark of instance finding.

#![allow(dead_code)]

use dggt_geom::glam::{DQuat, DVec3};
use dggt_instances::{RigidMotion, ViewPoints};

/// The camera's image size and focal length (pixels).
#[derive(Debug, Clone, Copy)]
pub struct Camera {
    pub width: usize,
    pub height: usize,
    pub focal: f64,
}

/// The tests' camera.
pub const SMALL: Camera = Camera { width: 160, height: 96, focal: 120.0 };

/// A car-sized box (x forward, y left, z up from the road at y = 1.5 m below the camera) at a pose.
#[derive(Clone, Copy)]
pub struct Car {
    pub centre: DVec3,
    pub heading: f64,
}

impl Car {
    const HALF: DVec3 = DVec3::new(2.25, 0.95, 0.75);

    fn rotation(&self) -> DQuat {
        // Camera axes (OpenCV: x right, y down, z forward); the road plane is x-z, "up" is -y.
        DQuat::from_rotation_y(-self.heading)
    }

    /// Ray parameter of the first hit of `origin + s · direction` with the box, if any.
    fn hit(&self, direction: DVec3) -> Option<f64> {
        let inverse = self.rotation().inverse();
        let (origin, direction) = (inverse * -self.centre, inverse * direction);
        // The box in its own frame: x along its length, z across, y vertical (camera axes turned).
        let half = DVec3::new(Self::HALF.x, Self::HALF.z, Self::HALF.y);
        let (entry, _) = dggt_geom::ray_box_interval(origin, direction, half)?;
        (entry > 0.0).then_some(entry)
    }

    /// The world motion taking this pose's points to `other`'s.
    pub fn motion_to(&self, other: &Car) -> RigidMotion {
        let rotation = other.rotation() * self.rotation().inverse();
        RigidMotion { rotation, translation: other.centre - rotation * self.centre }
    }
}

/// The turning car: the car ahead, driving away from the camera and turning left through a curve of radius
/// 10 m at 8 m per unit of time, 0.8 rad over the three inputs (the camera sees its rear and its right side).
pub fn turning(time: f64) -> Car {
    let angle = 0.25 + time * 0.8;
    let turn_centre = DVec3::new(-9.0, 0.75, 10.0);
    let centre = turn_centre + DVec3::new(10.0 * angle.cos(), 0.0, 10.0 * angle.sin());
    Car { centre, heading: std::f64::consts::FRAC_PI_2 + angle }
}

pub fn straight(time: f64) -> Car {
    Car { centre: DVec3::new(9.0, 0.75, 30.0 - 8.0 * time), heading: std::f64::consts::PI }
}

/// The point map and dynamic probabilities of `camera` at `time`.
pub fn view(camera: Camera, time: f64, with_cars: bool) -> (Vec<[f32; 3]>, Vec<f32>) {
    let Camera { width, height, focal } = camera;
    let mut points = Vec::with_capacity(width * height);
    let mut dynamic = Vec::with_capacity(width * height);
    for row in 0..height {
        for column in 0..width {
            let direction = DVec3::new(
                (column as f64 + 0.5 - width as f64 / 2.0) / focal,
                (row as f64 + 0.5 - height as f64 / 2.0) / focal,
                1.0,
            );
            let car = [turning(time), straight(time)]
                .iter()
                .filter(|_| with_cars)
                .filter_map(|car| car.hit(direction))
                .min_by(f64::total_cmp);
            let (depth, moving) = match car {
                Some(s) => (s, 0.95),
                None => (60.0, 0.02),
            };
            points.push((direction * depth).to_array().map(|v| v as f32));
            dynamic.push(moving);
        }
    }
    (points, dynamic)
}

/// A view's time, point map and dynamic probabilities.
pub type PointMap = (f64, Vec<[f32; 3]>, Vec<f32>);

/// The point maps of `camera` at `times`, each with or without the cars.
pub fn views_at(camera: Camera, times: &[(f64, bool)]) -> Vec<PointMap> {
    times
        .iter()
        .map(|&(time, cars)| {
            let (points, dynamic) = view(camera, time, cars);
            (time, points, dynamic)
        })
        .collect()
}

/// The maps as instance finding reads them.
pub fn points_of(camera: Camera, maps: &[PointMap]) -> Vec<ViewPoints<'_>> {
    maps.iter()
        .map(|(time, points, dynamic)| ViewPoints {
            rig_camera: 0,
            time: *time,
            width: camera.width,
            height: camera.height,
            camera_centre: DVec3::ZERO,
            pixel_angle: 1.0 / camera.focal,
            points,
            dynamic,
            velocity: None,
        })
        .collect()
}
