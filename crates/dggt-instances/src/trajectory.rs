//! An object's rigid trajectory through the input times, and its pose at any time between them.
//!
//! The object's points at its first input time are its reference; key `k` (at input time `t_k`) is the motion
//! taking reference points to where they are at `t_k`. Between two keys the object moves along the screw of the
//! step between them ([`RigidMotion::screw_fraction`]): its rotation is the SLERP of the step's, and its points
//! turn about the step's own axis rather than about a chosen centre, so a car turning at a constant rate follows
//! its arc (a centre moved linearly would cut the chord: 0.2 m inside a 10 m radius over 0.4 rad), and a car
//! driving straight moves linearly. Before the first key and after the last it is held at the end pose (an object
//! is not extrapolated beyond what the inputs saw). Times are scene times; positions are in the reconstruction's
//! world.

use dggt_geom::glam::DVec3;

use crate::rigid::RigidMotion;

/// A key pose of a [`Trajectory`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeyPose {
    /// Scene time of the input.
    pub time: f64,
    /// Takes the object's reference points to where they are at `time`.
    pub from_reference: RigidMotion,
}

/// Key poses at increasing input times, from the reference (identity) on.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    reference_centre: DVec3,
    keys: Vec<KeyPose>,
}

impl Trajectory {
    /// A trajectory seen once, at `time`, with its points' centroid at `centre`: held there.
    pub fn start(time: f64, centre: DVec3) -> Self {
        Self { reference_centre: centre, keys: vec![KeyPose { time, from_reference: RigidMotion::IDENTITY }] }
    }

    /// Appends the key at `time` reached from the last key by `step` (world points at the last key's time to
    /// world points at `time`). `time` must be later than the last key's.
    pub fn push(&mut self, time: f64, step: &RigidMotion) {
        let last = *self.keys.last().expect("a trajectory has its reference key");
        debug_assert!(time > last.time, "keys at increasing times");
        let mut from_reference = step.after(&last.from_reference);
        from_reference.rotation = from_reference.rotation.normalize();
        self.keys.push(KeyPose { time, from_reference });
    }

    /// A trajectory from its keys (as [`Trajectory::keys`] gives them) and reference centroid; `None` unless
    /// there is at least one key, the times increase and every value is finite.
    pub fn from_keys(reference_centre: DVec3, keys: Vec<KeyPose>) -> Option<Self> {
        let finite = reference_centre.is_finite()
            && keys.iter().all(|key| key.time.is_finite() && key.from_reference.is_finite());
        let increasing = keys.windows(2).all(|pair| pair[0].time < pair[1].time);
        (finite && increasing && !keys.is_empty()).then_some(Self { reference_centre, keys })
    }

    pub fn keys(&self) -> &[KeyPose] {
        &self.keys
    }

    /// Where the reference centroid is at `time`.
    pub fn centre(&self, time: f64) -> DVec3 {
        self.pose(time).apply(self.reference_centre)
    }

    /// The motion from the reference to `time` (see the module's doc).
    pub fn pose(&self, time: f64) -> RigidMotion {
        match self.segment(time) {
            Segment::Key(key) => key.from_reference,
            Segment::Between(a, b, w) => {
                let step = b.from_reference.after(&a.from_reference.inverse());
                step.screw_fraction(w).after(&a.from_reference)
            }
        }
    }

    /// The motion of the object's points from time `from` to time `to`: `pose(to) ∘ pose(from)⁻¹`; exactly the
    /// identity when `from == to`.
    pub fn motion(&self, from: f64, to: f64) -> RigidMotion {
        if from == to {
            return RigidMotion::IDENTITY;
        }
        let mut motion = self.pose(to).after(&self.pose(from).inverse());
        motion.rotation = motion.rotation.normalize();
        motion
    }

    /// The velocity (world units per unit of scene time) at time `at` of the object's point that is at `point`
    /// then: the twist of the step `at` lies in (the step starting at `at`; the last step at the last key's
    /// time); zero for an object seen once.
    pub fn point_velocity(&self, at: f64, point: DVec3) -> DVec3 {
        let keys = &self.keys;
        if keys.len() < 2 {
            return DVec3::ZERO;
        }
        let after = keys.partition_point(|key| key.time <= at).clamp(1, keys.len() - 1);
        let (a, b) = (keys[after - 1], keys[after]);
        let step = b.from_reference.after(&a.from_reference.inverse());
        step.screw_velocity(point) / (b.time - a.time)
    }

    /// The reference centroid (the object's centre at its first input time).
    pub fn reference_centre(&self) -> DVec3 {
        self.reference_centre
    }

    fn segment(&self, time: f64) -> Segment {
        let keys = &self.keys;
        let after = keys.partition_point(|key| key.time <= time);
        if after == 0 {
            return Segment::Key(keys[0]);
        }
        let a = keys[after - 1];
        if after == keys.len() || time == a.time {
            return Segment::Key(a);
        }
        let b = keys[after];
        Segment::Between(a, b, (time - a.time) / (b.time - a.time))
    }
}

/// Where a time falls among the keys.
enum Segment {
    /// At a key, or held before the first or after the last.
    Key(KeyPose),
    /// Between two keys, at fraction `w` of the way.
    Between(KeyPose, KeyPose, f64),
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::glam::DQuat;

    fn turning() -> (Trajectory, RigidMotion) {
        let mut trajectory = Trajectory::start(0.25, DVec3::new(10.0, 2.0, 0.8));
        let step = RigidMotion { rotation: DQuat::from_rotation_z(0.3), translation: DVec3::new(1.0, 0.5, 0.0) };
        trajectory.push(0.5, &step);
        trajectory.push(1.0, &step);
        (trajectory, step)
    }

    #[test]
    fn at_the_keys_the_motion_is_the_registered_one() {
        let (trajectory, step) = turning();
        let point = DVec3::new(11.0, 1.5, 1.2);
        assert_eq!(trajectory.motion(0.5, 0.5), RigidMotion::IDENTITY);
        assert!(trajectory.motion(0.25, 0.5).apply(point).abs_diff_eq(step.apply(point), 1e-12));
        let twice = step.after(&step).apply(point);
        assert!(trajectory.motion(0.25, 1.0).apply(point).abs_diff_eq(twice, 1e-12));
        // Backwards is the inverse.
        let back = trajectory.motion(1.0, 0.5).apply(step.apply(point));
        assert!(back.abs_diff_eq(point, 1e-12), "{back}");
    }

    #[test]
    fn between_keys_the_object_turns_evenly_and_is_held_outside() {
        let (trajectory, step) = turning();
        let half = trajectory.motion(0.5, 0.75);
        assert!((half.angle() - 0.15).abs() < 1e-12, "{}", half.angle());
        // Two halves make the step.
        let point = DVec3::new(9.0, 3.0, 0.0);
        let halves = trajectory.motion(0.75, 1.0).after(&half);
        assert!(halves.apply(point).abs_diff_eq(step.apply(point), 1e-12));
        assert_eq!(trajectory.pose(-3.0), RigidMotion::IDENTITY);
        assert_eq!(trajectory.pose(9.0), trajectory.keys()[2].from_reference);
        assert!(trajectory.centre(0.25).abs_diff_eq(DVec3::new(10.0, 2.0, 0.8), 0.0));
    }

    #[test]
    fn point_velocity_is_the_derivative_of_the_motion() {
        let (trajectory, _) = turning();
        let point = DVec3::new(12.0, 3.0, 0.5);
        for at in [0.25, 0.4, 0.5, 0.8] {
            let h = 1e-6;
            let numeric = (trajectory.motion(at, at + h).apply(point) - point) / h;
            let analytic = trajectory.point_velocity(at, point);
            assert!(numeric.abs_diff_eq(analytic, 1e-5), "{at}: {numeric} vs {analytic}");
        }
        assert_eq!(Trajectory::start(0.0, DVec3::ONE).point_velocity(0.0, DVec3::ZERO), DVec3::ZERO);
    }
}
