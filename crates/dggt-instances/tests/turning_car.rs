//! Instances found in ray-cast point maps of a car turning through a curve and a car driving straight, seen
//! by one forward-looking camera at three input times (0, 0.5 and 1, each car driving 4 m between them): each car is one instance over all three times, and its
//! trajectory moves its points where the truth has them, between the inputs too.

use dggt_geom::glam::{DQuat, DVec3};
use dggt_instances::{InstanceSettings, RigidMotion, ViewPoints, find_instances};

const WIDTH: usize = 160;
const HEIGHT: usize = 96;
const FOCAL: f64 = 120.0;

/// A car-sized box (x forward, y left, z up from the road at y = 1.5 m below the camera) at a pose.
#[derive(Clone, Copy)]
struct Car {
    centre: DVec3,
    heading: f64,
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
        let (mut near, mut far) = (0.0f64, f64::INFINITY);
        for axis in 0..3 {
            let (o, d, h) = (origin[axis], direction[axis], half[axis]);
            if d.abs() < 1e-12 {
                if o.abs() > h {
                    return None;
                }
                continue;
            }
            let (a, b) = ((-h - o) / d, (h - o) / d);
            near = near.max(a.min(b));
            far = far.min(a.max(b));
        }
        (near <= far && near > 0.0).then_some(near)
    }

    /// The world motion taking this pose's points to `other`'s.
    fn motion_to(&self, other: &Car) -> RigidMotion {
        let rotation = other.rotation() * self.rotation().inverse();
        RigidMotion { rotation, translation: other.centre - rotation * self.centre }
    }
}

/// The turning car: the car ahead, driving away from the camera and turning left through a curve of radius
/// 10 m at 8 m per unit of time, 0.8 rad over the three inputs (the camera sees its rear and its right side).
fn turning(time: f64) -> Car {
    let angle = 0.25 + time * 0.8;
    let turn_centre = DVec3::new(-9.0, 0.75, 10.0);
    let centre = turn_centre + DVec3::new(10.0 * angle.cos(), 0.0, 10.0 * angle.sin());
    Car { centre, heading: std::f64::consts::FRAC_PI_2 + angle }
}

fn straight(time: f64) -> Car {
    Car { centre: DVec3::new(9.0, 0.75, 30.0 - 8.0 * time), heading: std::f64::consts::PI }
}

/// The point map and dynamic probabilities of the camera at the origin at `time`.
fn view(time: f64, with_cars: bool) -> (Vec<[f32; 3]>, Vec<f32>) {
    let mut points = Vec::with_capacity(WIDTH * HEIGHT);
    let mut dynamic = Vec::with_capacity(WIDTH * HEIGHT);
    for row in 0..HEIGHT {
        for column in 0..WIDTH {
            let direction = DVec3::new(
                (column as f64 + 0.5 - WIDTH as f64 / 2.0) / FOCAL,
                (row as f64 + 0.5 - HEIGHT as f64 / 2.0) / FOCAL,
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
type PointMap = (f64, Vec<[f32; 3]>, Vec<f32>);

fn views_at(times: &[(f64, bool)]) -> Vec<PointMap> {
    times
        .iter()
        .map(|&(time, cars)| {
            let (points, dynamic) = view(time, cars);
            (time, points, dynamic)
        })
        .collect()
}

fn points_of(maps: &[PointMap]) -> Vec<ViewPoints<'_>> {
    maps.iter()
        .map(|(time, points, dynamic)| ViewPoints {
            rig_camera: 0,
            time: *time,
            width: WIDTH,
            height: HEIGHT,
            camera_centre: DVec3::ZERO,
            points,
            dynamic,
            velocity: None,
        })
        .collect()
}

#[test]
fn each_car_is_one_instance_whose_trajectory_follows_the_truth() {
    let maps = views_at(&[(0.0, true), (0.5, true), (1.0, true)]);
    let instances = find_instances(&points_of(&maps), &InstanceSettings::default());
    assert_eq!(instances.len(), 2, "{:?}", instances.instances.iter().map(|i| &i.appearances).collect::<Vec<_>>());
    for instance in &instances.instances {
        assert_eq!(instance.appearances.len(), 3, "instance {} seen at every input", instance.id);
    }
    // Which instance is which car: the straight one drives 9 m to the right.
    let turning_id = instances.instances.iter().position(|i| i.appearances[0].centre.x < 5.0).unwrap();
    let truth =
        |time: f64| if turning_id == 0 { [turning(time), straight(time)] } else { [straight(time), turning(time)] };
    // Points of each car at time 0 (the ones the camera saw) moved by the trajectory land within 0.3 m on
    // average (the cars drive 4 m between inputs) of where the true motion takes them, at the inputs and between
    // them.
    let (_, points, _) = &maps[0];
    for (position, instance) in instances.instances.iter().enumerate() {
        let own: Vec<DVec3> = (0..WIDTH * HEIGHT)
            .filter(|&pixel| instances.instance_of(0, pixel) == Some(position))
            .map(|pixel| DVec3::from_array(points[pixel].map(f64::from)))
            .collect();
        assert!(own.len() > 40, "instance {} has {} pixels at time 0", instance.id, own.len());
        for time in [0.25, 0.5, 0.75, 1.0] {
            let predicted = instances.motion(position, 0.0, time);
            let actual = truth(0.0)[position].motion_to(&truth(time)[position]);
            let errors: Vec<f64> = own.iter().map(|&p| predicted.apply(p).distance(actual.apply(p))).collect();
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            let largest = errors.iter().fold(0.0f64, |a, &b| a.max(b));
            assert!(
                mean < 0.3 && largest < 0.4,
                "instance {} at t = {time}: errors mean {mean} m, largest {largest} m",
                instance.id
            );
        }
    }
    // At the next input, the turning car's trajectory beats moving each point on with its exact velocity at
    // time 0 (the per-pixel velocity source at its best).
    let own: Vec<DVec3> = (0..WIDTH * HEIGHT)
        .filter(|&pixel| instances.instance_of(0, pixel) == Some(turning_id))
        .map(|pixel| DVec3::from_array(points[pixel].map(f64::from)))
        .collect();
    let actual = turning(0.0).motion_to(&turning(0.5));
    let h = 1e-6;
    let instant = turning(0.0).motion_to(&turning(h));
    let constant_velocity = |p: DVec3| p + (instant.apply(p) - p) / h * 0.5;
    let mean_error = |f: &dyn Fn(DVec3) -> DVec3| {
        own.iter().map(|&p| f(p).distance(actual.apply(p))).sum::<f64>() / own.len() as f64
    };
    let trajectory_error = mean_error(&|p| instances.motion(turning_id, 0.0, 0.5).apply(p));
    let velocity_error = mean_error(&constant_velocity);
    assert!(trajectory_error < velocity_error / 2.0, "trajectory {trajectory_error} m, velocity {velocity_error} m");
}

#[test]
fn a_time_without_dynamic_pixels_ends_the_instances() {
    let maps = views_at(&[(0.0, true), (0.5, false)]);
    let instances = find_instances(&points_of(&maps), &InstanceSettings::default());
    assert_eq!(instances.len(), 2);
    assert!(instances.instances.iter().all(|i| i.appearances.len() == 1 && i.residuals.is_empty()));
    // Seen once: held everywhere.
    assert_eq!(instances.motion(0, 0.0, 0.5), RigidMotion::IDENTITY);
    let none = views_at(&[(0.0, false), (0.5, false)]);
    let instances = find_instances(&points_of(&none), &InstanceSettings::default());
    assert!(instances.is_empty() && (0..WIDTH * HEIGHT).all(|p| instances.instance_of(1, p).is_none()));
}
