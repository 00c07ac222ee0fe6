//! Tracks: each annotated object's boxes over the log, by time, and what follows from them: whether the object
//! moves ([`Tracks::speed_at`]) and where its box is at a time between annotations ([`Tracks::box_at`]), such as
//! the moment a camera fired, which is not the moment the boxes were annotated at.
//!
//! Conventions: boxes are in the log's world ([`LogWorld`]); times are seconds on the log's clock (any origin
//! shared by every call). A box between two annotations is interpolated (translation and size linearly, rotation
//! by slerp); a time up to [`MAX_EXTRAPOLATION_S`] outside the track's span continues the nearest interval's
//! motion; further out the object has no box. Speeds are horizontal (x, y of the world, z up), in m/s, taken over
//! a window of [`SPEED_WINDOW_S`] centred on the time (clamped to the track's span), so that annotation jitter
//! between consecutive frames is not mistaken for motion.

use std::collections::HashMap;

use dggt_geom::glam::DVec3;
use dggt_geom::{Ego, LogWorld, Rigid, interpolate_rigid};

use crate::box_flow::WorldBox;
use crate::boxes::{AnnotatedBox, ObjectBox};

/// The window a speed is measured over (s): a second, as long as two nuScenes key-frame intervals.
pub const SPEED_WINDOW_S: f64 = 1.0;

/// How far beyond its first or last annotation a track is continued (s): a camera fires up to a tenth of a
/// second before its sweep's annotations (PandaSet, nuScenes), so the first frame's boxes need this much.
pub const MAX_EXTRAPOLATION_S: f64 = 0.15;

/// The speed (m/s) above which an object counts as moving by default: parked boxes of real logs jitter by a few
/// centimetres between annotations (a few cm/s over the window), a walking person moves at about 1.2 m/s.
pub const DEFAULT_MOVING_SPEED_M_S: f64 = 0.5;

/// One annotation of a track.
#[derive(Debug, Clone, PartialEq)]
struct TrackPoint {
    time_s: f64,
    world_from_box: Rigid<LogWorld, ObjectBox>,
    size: DVec3,
}

/// Every object's annotations, by id, in time order.
#[derive(Debug, Clone, Default)]
pub struct Tracks {
    by_id: HashMap<String, Vec<TrackPoint>>,
}

impl Tracks {
    /// Tracks from frames of boxes: `(time_s, boxes)` in any order.
    pub fn new<'a>(frames: impl IntoIterator<Item = (f64, &'a [WorldBox])>) -> Self {
        let mut by_id: HashMap<String, Vec<TrackPoint>> = HashMap::new();
        for (time_s, boxes) in frames {
            for object in boxes {
                let point = TrackPoint { time_s, world_from_box: object.world_from_box, size: object.size };
                by_id.entry(object.id.clone()).or_default().push(point);
            }
        }
        for points in by_id.values_mut() {
            points.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
            points.dedup_by(|later, earlier| later.time_s == earlier.time_s);
        }
        Self { by_id }
    }

    /// The annotations of object `id` (at least one), when its track reaches `time_s` (its span extended by
    /// [`MAX_EXTRAPOLATION_S`] either side).
    fn reaching(&self, id: &str, time_s: f64) -> Option<&[TrackPoint]> {
        let points = self.by_id.get(id)?;
        let (first, last) = (points.first()?, points.last()?);
        let reaches = time_s >= first.time_s - MAX_EXTRAPOLATION_S && time_s <= last.time_s + MAX_EXTRAPOLATION_S;
        reaches.then_some(points.as_slice())
    }

    /// The object's horizontal speed (m/s) around `time_s`: the displacement of its box centre between the
    /// window's ends (clamped to the track's span) over their time apart; 0 for a track of one annotation, `None`
    /// for an unknown object or a time outside the track's (extended) span.
    pub fn speed_at(&self, id: &str, time_s: f64) -> Option<f64> {
        let points = self.reaching(id, time_s)?;
        let (first, last) = (&points[0], &points[points.len() - 1]);
        let start = (time_s - SPEED_WINDOW_S / 2.0).clamp(first.time_s, last.time_s);
        let end = (time_s + SPEED_WINDOW_S / 2.0).clamp(first.time_s, last.time_s);
        if end <= start {
            return Some(0.0);
        }
        let (a, b) = (centre_at(points, start), centre_at(points, end));
        Some((b - a).truncate().length() / (end - start))
    }

    /// The object's box at `time_s` (see the module's rules), or `None` for an unknown object or a time outside
    /// its track's extended span.
    pub fn box_at(&self, id: &str, time_s: f64) -> Option<WorldBox> {
        let (earlier, later) = bracket(self.reaching(id, time_s)?, time_s);
        if earlier.time_s == later.time_s {
            return Some(WorldBox { id: id.to_owned(), world_from_box: earlier.world_from_box, size: earlier.size });
        }
        let fraction = (time_s - earlier.time_s) / (later.time_s - earlier.time_s);
        // Rotations that cannot be blended (not finite) leave the nearer annotation's pose.
        let nearer = if fraction < 0.5 { earlier } else { later };
        let world_from_box = interpolate_rigid(&earlier.world_from_box, &later.world_from_box, fraction)
            .unwrap_or(nearer.world_from_box);
        let size = earlier.size.lerp(later.size, fraction.clamp(0.0, 1.0));
        Some(WorldBox { id: id.to_owned(), world_from_box, size })
    }
}

impl Tracks {
    /// `object` (annotated in some frame) as a view at `time_s` sees it, in the ego frame whose world pose is
    /// `world_from_ego`: moved along its track to that time and given its track's speed there. An object whose
    /// track does not reach the time keeps its pose and gets speed 0.
    pub fn at_view(
        &self,
        mut object: AnnotatedBox,
        time_s: f64,
        world_from_ego: &Rigid<LogWorld, Ego>,
    ) -> AnnotatedBox {
        if let Some(moved) = self.box_at(&object.id, time_s) {
            object.ego_from_box = world_from_ego.inverse() * moved.world_from_box;
            object.size = moved.size;
        }
        object.speed = self.speed_at(&object.id, time_s).unwrap_or(0.0);
        object
    }
}

/// The two annotations around `time_s`: the interval holding it, the first or last interval outside the span,
/// or the one annotation twice for a track of one.
fn bracket(points: &[TrackPoint], time_s: f64) -> (&TrackPoint, &TrackPoint) {
    if points.len() == 1 {
        return (&points[0], &points[0]);
    }
    let after = points.partition_point(|p| p.time_s <= time_s).clamp(1, points.len() - 1);
    (&points[after - 1], &points[after])
}

/// The box centre at a time inside the track's span.
fn centre_at(points: &[TrackPoint], time_s: f64) -> DVec3 {
    let (earlier, later) = bracket(points, time_s);
    if earlier.time_s == later.time_s {
        return earlier.world_from_box.translation();
    }
    let fraction = (time_s - earlier.time_s) / (later.time_s - earlier.time_s);
    earlier.world_from_box.translation().lerp(later.world_from_box.translation(), fraction)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::glam::DQuat;

    fn object(id: &str, x: f64, y: f64, yaw: f64) -> WorldBox {
        WorldBox {
            id: id.into(),
            world_from_box: Rigid::from_rotation_translation(DQuat::from_rotation_z(yaw), DVec3::new(x, y, 1.0))
                .unwrap(),
            size: DVec3::new(4.0, 2.0, 1.5),
        }
    }

    /// A car driving along x at 10 m/s and a parked one, annotated at 10 Hz for a second.
    fn log() -> Vec<(f64, Vec<WorldBox>)> {
        (0..=10)
            .map(|i| (i as f64 * 0.1, vec![object("car", i as f64, 0.0, 0.0), object("parked", 5.0, 3.0, 0.3)]))
            .collect()
    }

    fn tracks(frames: &[(f64, Vec<WorldBox>)]) -> Tracks {
        Tracks::new(frames.iter().map(|(t, boxes)| (*t, boxes.as_slice())))
    }

    #[test]
    fn speeds_tell_the_moving_car_from_the_parked_one_across_the_whole_track() {
        let tracks = tracks(&log());
        for time in [0.0, 0.25, 0.5, 1.0, 1.1] {
            assert!((tracks.speed_at("car", time).unwrap() - 10.0).abs() < 1e-9, "at {time}");
            assert_eq!(tracks.speed_at("parked", time), Some(0.0));
        }
        assert_eq!(tracks.speed_at("car", 1.2), None, "past the extension");
        assert_eq!(tracks.speed_at("bus", 0.5), None);
    }

    #[test]
    fn jitter_of_a_parked_box_stays_under_the_moving_speed() {
        let frames: Vec<_> =
            (0..=10).map(|i| (i as f64 * 0.1, vec![object("parked", 5.0 + 0.05 * (i % 2) as f64, 3.0, 0.0)])).collect();
        let speed = tracks(&frames).speed_at("parked", 0.5).unwrap();
        assert!(speed < 0.1 * DEFAULT_MOVING_SPEED_M_S, "{speed}");
    }

    #[test]
    fn a_box_between_and_just_before_annotations_follows_the_motion() {
        let tracks = tracks(&log());
        let between = tracks.box_at("car", 0.35).unwrap();
        assert!(between.world_from_box.translation().abs_diff_eq(DVec3::new(3.5, 0.0, 1.0), 1e-9));
        let before = tracks.box_at("car", -0.1).unwrap();
        assert!(before.world_from_box.translation().abs_diff_eq(DVec3::new(-1.0, 0.0, 1.0), 1e-9));
        assert!(tracks.box_at("car", -0.2).is_none());
        let parked = tracks.box_at("parked", 0.77).unwrap();
        assert!(parked.world_from_box.max_abs_difference(&object("parked", 5.0, 3.0, 0.3).world_from_box) < 1e-9);
    }

    #[test]
    fn a_turning_box_turns_between_annotations() {
        let frames = vec![(0.0, vec![object("car", 0.0, 0.0, 0.0)]), (1.0, vec![object("car", 0.0, 0.0, 1.0)])];
        let half = tracks(&frames).box_at("car", 0.5).unwrap();
        let expected = DQuat::from_rotation_z(0.5);
        assert!(half.world_from_box.rotation().angle_between(expected) < 1e-6);
    }

    #[test]
    fn a_single_annotation_stands_still() {
        let frames = vec![(2.0, vec![object("once", 1.0, 2.0, 0.0)])];
        let tracks = tracks(&frames);
        assert_eq!(tracks.speed_at("once", 2.0), Some(0.0));
        assert_eq!(tracks.box_at("once", 2.1).unwrap().world_from_box, frames[0].1[0].world_from_box);
    }
}
