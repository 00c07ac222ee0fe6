//! Instances found in ray-cast point maps of a car turning through a curve and a car driving straight, seen by
//! one forward-looking camera at three input times (0, 0.5 and 1, each car driving 4 m between them): each car
//! is one instance over all three times, and its trajectory moves its points where the truth has them, between
//! the inputs too; at the tests' resolution and at the main job's.

mod common;

use common::cars::{Camera, SMALL, straight, turning, views_at as maps_at};
use dggt_geom::glam::DVec3;
use dggt_instances::{InstanceSettings, RigidMotion, ViewPoints, find_instances};

const WIDTH: usize = SMALL.width;
const HEIGHT: usize = SMALL.height;

/// The main job's network size (84 x 84, the fixture's field of view).
const FIXTURE: Camera = Camera { width: 84, height: 84, focal: 63.0 };

fn views_at(times: &[(f64, bool)]) -> Vec<common::cars::PointMap> {
    maps_at(SMALL, times)
}

fn points_of(maps: &[common::cars::PointMap]) -> Vec<ViewPoints<'_>> {
    common::cars::points_of(SMALL, maps)
}

#[test]
fn each_car_is_one_instance_whose_trajectory_follows_the_truth() {
    follows_the_truth(SMALL, 0.1);
}

#[test]
fn at_the_main_jobs_resolution_too() {
    follows_the_truth(FIXTURE, 0.5);
}

/// Each car one instance seen at every input; its points moved by the trajectory within `tolerance` metres on
/// average of the truth.
fn follows_the_truth(camera: Camera, tolerance: f64) {
    let maps = maps_at(camera, &[(0.0, true), (0.5, true), (1.0, true)]);
    let instances = find_instances(&common::cars::points_of(camera, &maps), &InstanceSettings::default()).unwrap();
    assert_eq!(instances.len(), 2, "{:?}", instances.instances.iter().map(|i| &i.appearances).collect::<Vec<_>>());
    for instance in &instances.instances {
        assert_eq!(instance.appearances.len(), 3, "instance {} seen at every input", instance.id);
    }
    // Which instance is which car: the straight one drives 9 m to the right.
    let turning_id = instances.instances.iter().position(|i| i.appearances[0].centre.x < 5.0).unwrap();
    let truth =
        |time: f64| if turning_id == 0 { [turning(time), straight(time)] } else { [straight(time), turning(time)] };
    // Points of each car at time 0 (the ones the camera saw) moved by the trajectory land within the tolerance
    // on average (the cars drive 4 m between inputs) of where the true motion takes them, at the inputs and
    // between them.
    let (_, points, _) = &maps[0];
    for (position, instance) in instances.instances.iter().enumerate() {
        let own: Vec<DVec3> = (0..camera.width * camera.height)
            .filter(|&pixel| instances.instance_of(0, pixel) == Some(position))
            .map(|pixel| DVec3::from_array(points[pixel].map(f64::from)))
            .collect();
        assert!(own.len() > 20, "instance {} has {} pixels at time 0", instance.id, own.len());
        for time in [0.25, 0.5, 0.75, 1.0] {
            let predicted = instances.motion(position, 0.0, time);
            let actual = truth(0.0)[position].motion_to(&truth(time)[position]);
            let errors: Vec<f64> = own.iter().map(|&p| predicted.apply(p).distance(actual.apply(p))).collect();
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            let largest = errors.iter().fold(0.0f64, |a, &b| a.max(b));
            assert!(
                mean < tolerance && largest < tolerance + 0.1,
                "{camera:?}, instance {} at t = {time}: errors mean {mean} m, largest {largest} m",
                instance.id
            );
        }
    }
    // At the next input, the turning car's trajectory beats moving each point on with its exact velocity at
    // time 0 (the per-pixel velocity source at its best).
    let own: Vec<DVec3> = (0..camera.width * camera.height)
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
fn views_whose_buffers_do_not_match_their_size_are_errors() {
    let maps = views_at(&[(0.0, true)]);
    let mut views = points_of(&maps);
    views[0].dynamic = &views[0].dynamic[1..];
    let message = find_instances(&views, &InstanceSettings::default()).unwrap_err().to_string();
    assert!(message.contains("view 0") && message.contains("dynamic") && message.contains("15360"), "{message}");
}

#[test]
fn a_time_without_dynamic_pixels_ends_the_instances() {
    let maps = views_at(&[(0.0, true), (0.5, false)]);
    let instances = find_instances(&points_of(&maps), &InstanceSettings::default()).unwrap();
    assert_eq!(instances.len(), 2);
    assert!(instances.instances.iter().all(|i| i.appearances.len() == 1 && i.residuals.is_empty()));
    // Seen once: held everywhere.
    assert_eq!(instances.motion(0, 0.0, 0.5), RigidMotion::IDENTITY);
    let none = views_at(&[(0.0, false), (0.5, false)]);
    let instances = find_instances(&points_of(&none), &InstanceSettings::default()).unwrap();
    assert!(instances.is_empty() && (0..WIDTH * HEIGHT).all(|p| instances.instance_of(1, p).is_none()));
}
