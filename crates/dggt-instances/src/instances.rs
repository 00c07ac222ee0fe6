//! The moving objects of one forward pass: each with an id, its pixels and box at every input time it was seen,
//! and a rigid trajectory through those times ([`find_instances`]).

use dggt_geom::glam::{DQuat, DVec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::cluster::{ClusterSettings, ViewPoints, cluster_view};
use crate::link::{Group, LinkSettings, follow, group_at_time};
use crate::register::{RegistrationSettings, initial_motion, register};
use crate::rigid::RigidMotion;
use crate::trajectory::Trajectory;

/// Everything instance finding is asked.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InstanceSettings {
    pub cluster: ClusterSettings,
    pub link: LinkSettings,
    pub registration: RegistrationSettings,
}

/// One object at one input time.
#[derive(Debug, Clone, PartialEq)]
pub struct Appearance {
    /// Scene time of the input.
    pub time: f64,
    /// The input views it was seen in (indices into the views given), increasing.
    pub views: Vec<usize>,
    /// Its dynamic pixels over those views.
    pub pixels: usize,
    /// World-axis-aligned box of its points, `[min, max]`.
    pub bounds: [DVec3; 2],
    /// Centroid of its points.
    pub centre: DVec3,
}

/// One moving object.
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    /// Numbered from 0 in order of first appearance (earlier time first, then more pixels first).
    pub id: u32,
    /// One per input time it was seen at, in time order (consecutive input times).
    pub appearances: Vec<Appearance>,
    pub trajectory: Trajectory,
    /// Registration residual of each step between consecutive appearances (world units, root mean square of
    /// the kept pairs).
    pub residuals: Vec<f64>,
    /// A rigid change applied along the trajectory (an edit: the object turned about its own centre and
    /// shifted at every time); [`Placement::IDENTITY`] as found.
    pub placement: Placement,
}

/// A rigid change of an object applied along its trajectory: at every time `t` its points `y` are drawn at
/// `turn (y - c(t)) + c(t) + offset`, `c(t)` its centre then (world axes and units): the object is turned
/// about its own centre and shifted, and its path is shifted but not turned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// A unit quaternion.
    pub turn: DQuat,
    pub offset: DVec3,
}

impl Placement {
    pub const IDENTITY: Self = Self { turn: DQuat::IDENTITY, offset: DVec3::ZERO };

    /// The placement as a motion of world points when the object's centre is at `centre`.
    pub fn at(&self, centre: DVec3) -> RigidMotion {
        RigidMotion { rotation: self.turn, translation: centre + self.offset - self.turn * centre }
    }

    /// Whether every component is finite and `turn` is a unit quaternion (within `1e-6`).
    pub fn is_valid(&self) -> bool {
        self.turn.is_finite() && self.offset.is_finite() && (self.turn.length() - 1.0).abs() <= 1e-6
    }
}

/// The instances of a set of views, and which pixels belong to which.
#[derive(Debug, Clone, PartialEq)]
pub struct Instances {
    pub instances: Vec<Instance>,
    /// Per view, per pixel: the instance's position in `instances`, or [`Instances::NONE`].
    labels: Vec<Vec<u32>>,
}

impl Instances {
    /// Label of a pixel that belongs to no instance.
    pub const NONE: u32 = u32::MAX;

    /// The instance (position in [`Instances::instances`]) pixel `pixel` of view `view` belongs to.
    pub fn instance_of(&self, view: usize, pixel: usize) -> Option<usize> {
        let label = *self.labels.get(view)?.get(pixel)?;
        (label != Self::NONE).then_some(label as usize)
    }

    /// How many views the labels cover.
    pub fn views(&self) -> usize {
        self.labels.len()
    }

    /// The labels of view `view`, one per pixel ([`Instances::NONE`] for none).
    pub fn labels(&self, view: usize) -> &[u32] {
        &self.labels[view]
    }

    /// Instances with their per-view pixel labels (`labels[view][pixel]`: a position in `instances`, or
    /// [`Instances::NONE`]); `None` when a label names no instance.
    pub fn from_parts(instances: Vec<Instance>, labels: Vec<Vec<u32>>) -> Option<Self> {
        let valid = |&label: &u32| label == Self::NONE || (label as usize) < instances.len();
        labels.iter().flatten().all(valid).then_some(Self { instances, labels })
    }

    /// The motion of instance `instance`'s points from where they were found at scene time `from` to where
    /// they are drawn at `to`: its placement at `to` after `trajectory.motion(from, to)` (exactly the identity
    /// when `from == to` and the placement is the identity).
    pub fn motion(&self, instance: usize, from: f64, to: f64) -> RigidMotion {
        let found = &self.instances[instance];
        let motion = found.trajectory.motion(from, to);
        if found.placement == Placement::IDENTITY {
            return motion;
        }
        found.placement.at(found.trajectory.centre(to)).after(&motion)
    }

    /// The world velocity (world units per unit of scene time) at time `at` of instance `instance`'s point
    /// drawn at `point` then (see [`Trajectory::point_velocity`]), placed: `d/dt [E(t) y(t)]` for the
    /// placement `E(t) y = R (y - c(t)) + c(t) + offset` about the moving centre `c(t)`, i.e.
    /// `R y' + (I - R) c'`.
    pub fn point_velocity(&self, instance: usize, at: f64, point: DVec3) -> DVec3 {
        let found = &self.instances[instance];
        let trajectory = &found.trajectory;
        if found.placement == Placement::IDENTITY {
            return trajectory.point_velocity(at, point);
        }
        let centre = trajectory.centre(at);
        let unplaced = found.placement.at(centre).inverse().apply(point);
        let turn = found.placement.turn;
        let centre_velocity = trajectory.point_velocity(at, centre);
        turn * trajectory.point_velocity(at, unplaced) + centre_velocity - turn * centre_velocity
    }

    pub fn len(&self) -> usize {
        self.instances.len()
    }

    pub fn is_empty(&self) -> bool {
        self.instances.is_empty()
    }
}

/// A view whose buffers do not hold one entry per pixel.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("view {view}: {buffer} holds {actual} entries, expected {expected} (one per pixel of {width}x{height})")]
pub struct ShapeError {
    pub view: usize,
    pub buffer: &'static str,
    pub expected: usize,
    pub actual: usize,
    pub width: usize,
    pub height: usize,
}

/// Clusters every view's dynamic pixels, joins them per input time, follows them through consecutive input
/// times and registers each step (see the crate's doc). Views are given in any order; each view's buffers hold
/// `width · height` entries, or the view is named in the error.
pub fn find_instances(views: &[ViewPoints], settings: &InstanceSettings) -> Result<Instances, ShapeError> {
    for (position, view) in views.iter().enumerate() {
        let expected = view.width * view.height;
        let lengths = [("points", view.points.len()), ("dynamic", view.dynamic.len())]
            .into_iter()
            .chain(view.velocity.map(|v| ("velocity", v.len())));
        for (buffer, actual) in lengths {
            if actual != expected {
                return Err(ShapeError {
                    view: position,
                    buffer,
                    expected,
                    actual,
                    width: view.width,
                    height: view.height,
                });
            }
        }
    }
    let clusters: Vec<_> = views.par_iter().map(|view| cluster_view(view, &settings.cluster)).collect();
    let mut times: Vec<f64> = views.iter().map(|view| view.time).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let groups: Vec<Vec<Group>> =
        times.iter().map(|&time| group_at_time(views, &clusters, time, &settings.link)).collect();
    let chains = chains(&groups, &settings.link);
    let mut instances: Vec<Instance> =
        chains.par_iter().map(|chain| instance_of_chain(&groups, chain, &settings.registration)).collect();
    let mut labels: Vec<Vec<u32>> = views.iter().map(|view| vec![Instances::NONE; view.width * view.height]).collect();
    for (position, (instance, chain)) in instances.iter_mut().zip(&chains).enumerate() {
        instance.id = position as u32;
        for &(time, group) in chain {
            for &(view, pixel) in &groups[time][group].members {
                labels[view][pixel as usize] = position as u32;
            }
        }
    }
    Ok(Instances { instances, labels })
}

/// Each object as `(time position, group position)` steps through consecutive times, ordered by first time
/// then by size.
fn chains(groups: &[Vec<Group>], settings: &LinkSettings) -> Vec<Vec<(usize, usize)>> {
    let mut chains: Vec<Vec<(usize, usize)>> = Vec::new();
    // The chain each group of the previous time continues.
    let mut open: Vec<Option<usize>> = Vec::new();
    for (time, at_time) in groups.iter().enumerate() {
        let mut next_open = vec![None; at_time.len()];
        let pairs = if time == 0 { Vec::new() } else { follow(&groups[time - 1], at_time, settings) };
        for (earlier, later) in pairs {
            if let Some(chain) = open[earlier] {
                chains[chain].push((time, later));
                next_open[later] = Some(chain);
            }
        }
        let mut fresh: Vec<usize> = (0..at_time.len()).filter(|&g| next_open[g].is_none()).collect();
        fresh.sort_by_key(|&g| std::cmp::Reverse(at_time[g].members.len()));
        for group in fresh {
            next_open[group] = Some(chains.len());
            chains.push(vec![(time, group)]);
        }
        open = next_open;
    }
    chains
}

fn instance_of_chain(groups: &[Vec<Group>], chain: &[(usize, usize)], settings: &RegistrationSettings) -> Instance {
    let group = |&(time, position): &(usize, usize)| &groups[time][position];
    let first = group(&chain[0]);
    let mut trajectory = Trajectory::start(first.time, first.centre());
    let mut residuals = Vec::new();
    for step in chain.windows(2) {
        let (from, to) = (group(&step[0]), group(&step[1]));
        let elapsed = to.time - from.time;
        let displacement: Option<Vec<DVec3>> =
            from.velocities.as_ref().map(|velocities| velocities.iter().map(|v| *v * elapsed).collect());
        let start = initial_motion(&from.points, &to.points, displacement.as_deref());
        let registration = register(&from.points, &to.points, start, settings);
        let motion = registration.map_or(start, |r| r.motion);
        residuals.push(registration.map_or(f64::NAN, |r| r.residual));
        trajectory.push(to.time, &motion);
    }
    let appearances = chain
        .iter()
        .map(|step| {
            let group = group(step);
            let mut views: Vec<usize> = group.members.iter().map(|&(view, _)| view).collect();
            views.dedup();
            views.sort_unstable();
            views.dedup();
            Appearance {
                time: group.time,
                views,
                pixels: group.members.len(),
                bounds: group.bounds,
                centre: group.centre(),
            }
        })
        .collect();
    Instance { id: 0, appearances, trajectory, residuals, placement: Placement::IDENTITY }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One object turning through three keys, moved by `placement`, with one labelled pixel.
    fn placed(placement: Placement) -> Instances {
        let mut trajectory = Trajectory::start(0.0, DVec3::new(10.0, 2.0, 0.8));
        let step = RigidMotion { rotation: DQuat::from_rotation_z(0.3), translation: DVec3::new(1.0, 0.5, 0.0) };
        trajectory.push(0.5, &step);
        trajectory.push(1.0, &step);
        let instance = Instance { id: 0, appearances: Vec::new(), trajectory, residuals: vec![0.0; 2], placement };
        Instances::from_parts(vec![instance], vec![vec![0, Instances::NONE]]).unwrap()
    }

    #[test]
    fn a_placement_turns_the_object_about_its_centre_and_shifts_it_at_every_time() {
        let placement = Placement { turn: DQuat::from_rotation_z(0.4), offset: DVec3::new(0.0, 3.5, 0.0) };
        let (plain, moved) = (placed(Placement::IDENTITY), placed(placement));
        for time in [0.0, 0.3, 0.5, 0.8] {
            let centre = plain.instances[0].trajectory.centre(time);
            // The centre is shifted by the offset alone; a point beside it turns about it.
            let drawn = moved.motion(0, 0.0, time).apply(plain.instances[0].trajectory.reference_centre());
            assert!(drawn.abs_diff_eq(centre + placement.offset, 1e-9), "{time}: {drawn} vs {centre}");
            let beside = DVec3::new(12.0, 2.0, 0.8);
            let original = plain.motion(0, 0.0, time).apply(beside);
            let expected = centre + placement.offset + placement.turn * (original - centre);
            assert!(moved.motion(0, 0.0, time).apply(beside).abs_diff_eq(expected, 1e-9), "{time}");
        }
        assert_eq!(plain.motion(0, 0.5, 0.5), RigidMotion::IDENTITY, "no placement, no motion at a key");
    }

    #[test]
    fn a_placed_points_velocity_is_the_derivative_of_where_it_is_drawn() {
        let placement = Placement { turn: DQuat::from_rotation_z(-0.7), offset: DVec3::new(1.0, -2.0, 0.5) };
        let instances = placed(placement);
        let point = DVec3::new(11.0, 3.0, 1.0);
        let drawn = |t: f64| instances.motion(0, 0.0, t).apply(point);
        for at in [0.1, 0.3, 0.7, 0.9] {
            let h = 1e-6;
            let numeric = (drawn(at + h) - drawn(at - h)) / (2.0 * h);
            let analytic = instances.point_velocity(0, at, drawn(at));
            assert!(analytic.abs_diff_eq(numeric, 1e-5), "{at}: {analytic} vs {numeric}");
        }
    }

    #[test]
    fn labels_must_name_an_instance() {
        let instances = placed(Placement::IDENTITY);
        assert!(Instances::from_parts(instances.instances.clone(), vec![vec![1]]).is_none());
        assert_eq!(instances.views(), 1);
        assert_eq!(instances.instance_of(0, 0), Some(0));
        assert_eq!(instances.instance_of(0, 1), None);
    }
}
