//! One object's clusters joined within an input time, and followed from one input time to the next.
//!
//! Within a time, clusters whose bounds overlap (after growing both by [`LinkSettings::merge_margin`] of the
//! larger one's extent) are one object: the parts of an object split by an occluder in one view, or the same object seen by
//! two cameras of the rig. Between consecutive input times, every object of the earlier time is paired with at
//! most one of the later: the pair whose centres are closest, the earlier centre moved by its points' mean
//! predicted velocity when the network predicts one, first; a pair farther apart than
//! [`LinkSettings::gate`] times the larger of the two extents is not an object that moved but two objects.

use dggt_geom::glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::cluster::{Cluster, ViewPoints};
use crate::union_find::UnionFind;

/// How clusters are joined and followed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkSettings {
    /// Clusters of one time are joined when their bounds, both grown by this fraction of the larger extent,
    /// overlap.
    pub merge_margin: f64,
    /// Objects of consecutive times are followed when their (predicted) centres are within this many times
    /// the larger extent (a car at 30 m/s covers nearly three of its lengths between inputs 0.4 s apart).
    pub gate: f64,
}

impl Default for LinkSettings {
    fn default() -> Self {
        Self { merge_margin: 0.1, gate: 3.0 }
    }
}

/// The pixels of one object at one input time, over every view of that time.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    pub time: f64,
    /// `(view, pixel)` of every member pixel (views index the input views).
    pub members: Vec<(usize, u32)>,
    /// Their world points.
    pub points: Vec<DVec3>,
    /// Their predicted velocities (world units per unit of scene time), when predicted.
    pub velocities: Option<Vec<DVec3>>,
    pub bounds: [DVec3; 2],
}

impl Group {
    pub fn centre(&self) -> DVec3 {
        crate::register::centroid(&self.points)
    }

    pub fn extent(&self) -> f64 {
        (self.bounds[1] - self.bounds[0]).length()
    }

    fn mean_velocity(&self) -> DVec3 {
        match &self.velocities {
            Some(velocities) => crate::register::centroid(velocities),
            None => DVec3::ZERO,
        }
    }
}

/// The clusters of the views taken at `time` (`clusters[v]` belongs to `views[v]`) joined into groups.
pub fn group_at_time(
    views: &[ViewPoints],
    clusters: &[Vec<Cluster>],
    time: f64,
    settings: &LinkSettings,
) -> Vec<Group> {
    let at_time: Vec<(usize, &Cluster)> = views
        .iter()
        .enumerate()
        .filter(|(_, view)| view.time == time)
        .flat_map(|(v, _)| clusters[v].iter().map(move |cluster| (v, cluster)))
        .collect();
    let mut sets = UnionFind::new(at_time.len());
    for a in 0..at_time.len() {
        for b in a + 1..at_time.len() {
            let (one, other) = (at_time[a].1, at_time[b].1);
            let margin = DVec3::splat(settings.merge_margin * one.extent().max(other.extent()));
            let ([lo_a, hi_a], [lo_b, hi_b]) = (one.bounds, other.bounds);
            if (lo_a - margin).cmple(hi_b).all() && (lo_b - margin).cmple(hi_a).all() {
                sets.union(a, b);
            }
        }
    }
    let (labels, count) = sets.labels();
    let mut groups: Vec<Group> = (0..count)
        .map(|_| Group {
            time,
            members: Vec::new(),
            points: Vec::new(),
            velocities: None,
            bounds: [DVec3::INFINITY, DVec3::NEG_INFINITY],
        })
        .collect();
    for ((view, cluster), label) in at_time.into_iter().zip(labels) {
        let group = &mut groups[label];
        let source = &views[view];
        for &pixel in &cluster.pixels {
            group.members.push((view, pixel));
            group.points.push(DVec3::from_array(source.points[pixel as usize].map(f64::from)));
            if let Some(velocity) = source.velocity {
                let velocity = DVec3::from_array(velocity[pixel as usize].map(f64::from));
                group.velocities.get_or_insert_with(Vec::new).push(velocity);
            }
        }
        group.bounds = [group.bounds[0].min(cluster.bounds[0]), group.bounds[1].max(cluster.bounds[1])];
    }
    groups
}

/// Pairs `(earlier, later)` of indices into `earlier` and `later`, each index at most once, closest first.
pub fn follow(earlier: &[Group], later: &[Group], settings: &LinkSettings) -> Vec<(usize, usize)> {
    let later_centres: Vec<DVec3> = later.iter().map(Group::centre).collect();
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    for (a, from) in earlier.iter().enumerate() {
        let predicted =
            from.centre() + from.mean_velocity() * (later.first().map_or(from.time, |g| g.time) - from.time);
        for (b, to) in later.iter().enumerate() {
            let distance = predicted.distance(later_centres[b]);
            if distance <= settings.gate * from.extent().max(to.extent()) {
                candidates.push((distance, a, b));
            }
        }
    }
    candidates.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let (mut used_a, mut used_b) = (vec![false; earlier.len()], vec![false; later.len()]);
    let mut pairs = Vec::new();
    for (_, a, b) in candidates {
        if !used_a[a] && !used_b[b] {
            used_a[a] = true;
            used_b[b] = true;
            pairs.push((a, b));
        }
    }
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn group(time: f64, centre: DVec3, half: f64) -> Group {
        Group {
            time,
            members: vec![(0, 0)],
            points: vec![centre - DVec3::splat(half), centre + DVec3::splat(half)],
            velocities: None,
            bounds: [centre - DVec3::splat(half), centre + DVec3::splat(half)],
        }
    }

    #[test]
    fn objects_are_followed_by_the_closest_centres_within_the_gate() {
        let earlier = [group(0.0, DVec3::new(0.0, 0.0, 10.0), 1.0), group(0.0, DVec3::new(8.0, 0.0, 10.0), 1.0)];
        let later = [
            group(0.5, DVec3::new(9.0, 0.0, 10.0), 1.0),
            group(0.5, DVec3::new(1.0, 0.0, 10.0), 1.0),
            group(0.5, DVec3::new(30.0, 0.0, 10.0), 1.0),
        ];
        let mut pairs = follow(&earlier, &later, &LinkSettings::default());
        pairs.sort();
        assert_eq!(pairs, [(0, 1), (1, 0)]);
        // A tight gate follows nothing.
        assert!(follow(&earlier, &later, &LinkSettings { gate: 0.1, ..Default::default() }).is_empty());
        assert_eq!(follow(&earlier[..1], &later[2..], &LinkSettings::default()), []);
    }

    #[test]
    fn predicted_velocity_moves_the_earlier_centre() {
        // Two cars 4 m apart both drive 4 m forward: by centres alone the rear car would be taken for the front
        // one's successor; the velocities say otherwise.
        let moving =
            |x: f64| Group { velocities: Some(vec![DVec3::X * 8.0; 2]), ..group(0.0, DVec3::new(x, 0.0, 0.0), 1.0) };
        let earlier = [moving(0.0), moving(4.0)];
        let later = [group(0.5, DVec3::new(4.0, 0.0, 0.0), 1.0), group(0.5, DVec3::new(8.0, 0.0, 0.0), 1.0)];
        let mut pairs = follow(&earlier, &later, &LinkSettings::default());
        pairs.sort();
        assert_eq!(pairs, [(0, 0), (1, 1)]);
    }
}
