//! Analytic motion: the ego vehicle's drive along the road and the other cars' paths.
//!
//! A car follows a [`Path`] at constant speed: a straight approach, a circular arc and a straight exit (a
//! straight path is the special case of a zero turn). Position, heading, velocity and yaw rate are closed-form
//! functions of time, so the scene flow written to the export is exact rather than a finite difference.

use dggt_geom::glam::{DQuat, DVec2, DVec3};
use dggt_geom::{Rigid, World, WorldFromEgo};

/// The frame of a car's 3D box: origin at the box centre, x forward (length), y left (width), z up (height).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Object;

impl dggt_geom::frames::Frame for Object {
    const NAME: &'static str = "object box (centre origin, x forward, y left, z up)";
}

/// An object's pose: box coordinates into world points (the `obj_to_world` of the instance files).
pub type WorldFromObject = Rigid<World, Object>;

/// A rotation about +z by `heading` followed by a translation. Both must be finite; every caller derives them
/// from validated, finite scene parameters and times.
pub(crate) fn yaw_pose<To, From>(heading: f64, translation: DVec3) -> Rigid<To, From> {
    Rigid::from_rotation_translation(DQuat::from_rotation_z(heading), translation)
        .expect("poses are built from finite headings and positions")
}

/// A planar path parameterised by arc length `s`: for `s <= 0` the straight line through `entry` along
/// `heading`; for `0 < s < radius |turn|` a circular arc turning by `turn` radians (positive = left,
/// counter-clockwise seen from above); beyond that, a straight exit along `heading + turn`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Path {
    pub entry: DVec2,
    pub heading: f64,
    pub radius: f64,
    pub turn: f64,
}

/// Where a path is at one arc length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPoint {
    pub position: DVec2,
    pub heading: f64,
    /// Signed curvature (1/m, positive when turning left).
    pub curvature: f64,
}

fn direction(heading: f64) -> DVec2 {
    DVec2::new(heading.cos(), heading.sin())
}

impl Path {
    /// A straight line through `entry` along `heading`.
    pub fn straight(entry: DVec2, heading: f64) -> Self {
        Self { entry, heading, radius: 1.0, turn: 0.0 }
    }

    /// Length of the arc section.
    pub fn arc_length(&self) -> f64 {
        self.radius * self.turn.abs()
    }

    pub fn at(&self, s: f64) -> PathPoint {
        if s <= 0.0 || self.turn == 0.0 {
            return PathPoint {
                position: self.entry + direction(self.heading) * s,
                heading: self.heading,
                curvature: 0.0,
            };
        }
        let sign = self.turn.signum();
        let left = DVec2::new(-self.heading.sin(), self.heading.cos());
        let centre = self.entry + left * (sign * self.radius);
        let on_arc = |angle: f64| centre + DVec2::from_angle(angle).rotate(self.entry - centre);
        let length = self.arc_length();
        if s < length {
            let angle = sign * s / self.radius;
            PathPoint { position: on_arc(angle), heading: self.heading + angle, curvature: sign / self.radius }
        } else {
            let heading = self.heading + self.turn;
            PathPoint { position: on_arc(self.turn) + direction(heading) * (s - length), heading, curvature: 0.0 }
        }
    }
}

/// A car driving a [`Path`] at constant `speed`, reaching the path's entry (`s = 0`) at `time_at_entry`.
/// `centre_height` is the height of its box centre above the road.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarMotion {
    pub path: Path,
    pub speed: f64,
    pub time_at_entry: f64,
    pub centre_height: f64,
}

/// A car's rigid motion at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarState {
    /// World position of the box centre.
    pub position: DVec3,
    /// Yaw of the box's x axis from the world x axis (radians, counter-clockwise).
    pub heading: f64,
    /// World velocity of the box centre (m/s).
    pub velocity: DVec3,
    /// Angular velocity about the world z axis (rad/s).
    pub yaw_rate: f64,
}

impl CarMotion {
    pub fn state(&self, time: f64) -> CarState {
        let point = self.path.at(self.speed * (time - self.time_at_entry));
        CarState {
            position: point.position.extend(self.centre_height),
            heading: point.heading,
            velocity: (direction(point.heading) * self.speed).extend(0.0),
            yaw_rate: self.speed * point.curvature,
        }
    }
}

impl CarState {
    /// The box pose. Panics if the state is not finite (a state computed at a non-finite time).
    pub fn world_from_object(&self) -> WorldFromObject {
        yaw_pose(self.heading, self.position)
    }

    /// World velocity of a world point rigidly attached to the car: `v + ω ẑ × (p - c)`.
    pub fn point_velocity(&self, point: DVec3) -> DVec3 {
        let r = point - self.position;
        self.velocity + DVec3::new(-self.yaw_rate * r.y, self.yaw_rate * r.x, 0.0)
    }
}

/// The ego vehicle: forward along +x at `speed` with a gentle lateral sway
/// `y(t) = A (1 - cos(ω t))`, heading along its velocity. At `t = 0` the ego frame is the world frame, so the
/// world is anchored at the first ego pose exactly as scene-export readers anchor it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgoMotion {
    pub speed: f64,
    pub sway_amplitude: f64,
    pub sway_rate: f64,
}

impl EgoMotion {
    /// The ego pose (ego -> world) at `time`; the ego origin is on the road surface. Panics if `time` is not
    /// finite.
    pub fn pose(&self, time: f64) -> WorldFromEgo {
        let (a, w) = (self.sway_amplitude, self.sway_rate);
        let y = a * (1.0 - (w * time).cos());
        let heading = (a * w * (w * time).sin()).atan2(self.speed);
        yaw_pose(heading, DVec3::new(self.speed * time, y, 0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn turning_path_is_continuous_and_ends_where_expected() {
        let path = Path { entry: DVec2::new(10.0, 2.0), heading: std::f64::consts::PI, radius: 5.0, turn: -FRAC_PI_2 };
        let end = path.at(path.arc_length());
        assert!(end.position.abs_diff_eq(DVec2::new(5.0, 7.0), 1e-12), "{end:?}");
        assert!((end.heading - FRAC_PI_2).abs() < 1e-12);
        let mut previous = path.at(-3.0).position;
        for i in -29..200 {
            let p = path.at(i as f64 * 0.1).position;
            assert!(((p - previous).length() - 0.1).abs() < 1e-3, "step {i}");
            previous = p;
        }
    }

    #[test]
    fn velocity_matches_finite_difference() {
        let motion = CarMotion {
            path: Path { entry: DVec2::new(0.0, 0.0), heading: 0.3, radius: 4.0, turn: 1.2 },
            speed: 6.0,
            time_at_entry: 1.0,
            centre_height: 0.75,
        };
        let offset = DVec3::new(1.5, -0.7, 0.2);
        for time in [0.5, 1.3, 1.6, 2.5] {
            let at = |t: f64| motion.state(t).world_from_object().transform_point(offset);
            let h = 1e-5;
            let numeric = (at(time + h) - at(time - h)) / (2.0 * h);
            let state = motion.state(time);
            let analytic = state.point_velocity(state.world_from_object().transform_point(offset));
            assert!(numeric.abs_diff_eq(analytic, 1e-6), "{time}: {numeric} vs {analytic}");
        }
    }

    #[test]
    fn ego_starts_at_the_world_origin() {
        let ego = EgoMotion { speed: 8.0, sway_amplitude: 0.3, sway_rate: 0.7 };
        assert_eq!(ego.pose(0.0), WorldFromEgo::IDENTITY);
        assert!(ego.pose(1.0).translation().x == 8.0);
    }
}
