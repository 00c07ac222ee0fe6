//! How far the flow head would have to look to find where its queries truly go: given the true velocity of some
//! query rows, where each row's point truly is at its camera's next input time, which of that input's query
//! points is the true match (the one nearest the truly moved point), and how many of that input's query points
//! lie nearer the row's own point than the match. The head attends to the `k` target points nearest its current
//! estimate, starting from the row's own point: a match ranked beyond `k` is out of its first look.
//!
//! A diagnostic (a debug trace of the objective reads it); it runs on the host, brute force.

use dggt_model::host::host_f32;

use crate::error::SceneError;
use crate::learnt::{QUERY_LOGIT, adjacent_views};
use crate::pixels::PixelGaussians;

/// What [`PixelGaussians::flow_reach`] found, over the rows it could place.
#[derive(Debug, Clone, PartialEq)]
pub struct FlowReach {
    /// Rows with a true velocity, a next input of their camera and a target point there.
    pub rows: usize,
    /// The rank (1 = nearest) of each row's true match among the next input's query points, by distance from
    /// the row's own point: the median, and the 90th percentile.
    pub rank_median: usize,
    pub rank_p90: usize,
    /// Share of rows whose true match is among the `neighbours` nearest.
    pub within_neighbours: f64,
    /// The median true displacement to the next input (world units).
    pub displacement_median: f32,
    /// The median distance from the truly moved point to its match (world units): large when the object is not
    /// among the next input's query points.
    pub miss_median: f32,
}

impl PixelGaussians {
    /// The reach the flow head needs for rows of known motion: `truths` holds `(row, velocity)` with the
    /// velocity in world units per unit of scene time; `neighbours` is the head's `k`. `None` when no row has a
    /// next input of its camera with query points.
    pub fn flow_reach(&self, truths: &[(usize, [f32; 3])], neighbours: usize) -> Result<Option<FlowReach>, SceneError> {
        let Some(logit) = &self.dynamic_logit else { return Ok(None) };
        let logits = host_f32(logit.clone(), "dynamic logit")?;
        let per_view = self.per_view();
        let mut next = vec![None; self.views.len()];
        for (a, b) in adjacent_views(&self.views) {
            next[a] = Some(b);
        }
        let targets: Vec<Vec<[f32; 3]>> = (0..self.views.len())
            .map(|view| {
                (view * per_view..(view + 1) * per_view)
                    .filter(|&row| logits[row] >= QUERY_LOGIT)
                    .map(|row| self.host_means[row])
                    .collect()
            })
            .collect();
        let (mut ranks, mut displacements, mut misses) = (Vec::new(), Vec::new(), Vec::new());
        for &(row, velocity) in truths {
            let view = row / per_view;
            let Some(b) = next[view] else { continue };
            let cloud = &targets[b];
            if cloud.is_empty() {
                continue;
            }
            let span = (self.views[b].time - self.views[view].time) as f32;
            let start = self.host_means[row];
            let moved: [f32; 3] = std::array::from_fn(|i| start[i] + velocity[i] * span);
            let matched = cloud.iter().min_by(|p, q| distance(p, &moved).total_cmp(&distance(q, &moved))).copied();
            let Some(matched) = matched else { continue };
            let reach = distance(&matched, &start);
            ranks.push(1 + cloud.iter().filter(|p| distance(p, &start) < reach).count());
            displacements.push(distance(&moved, &start));
            misses.push(distance(&matched, &moved));
        }
        if ranks.is_empty() {
            return Ok(None);
        }
        let within = ranks.iter().filter(|&&r| r <= neighbours).count() as f64 / ranks.len() as f64;
        ranks.sort_unstable();
        Ok(Some(FlowReach {
            rows: ranks.len(),
            rank_median: ranks[ranks.len() / 2],
            rank_p90: ranks[ranks.len() * 9 / 10],
            within_neighbours: within,
            displacement_median: median(displacements),
            miss_median: median(misses),
        }))
    }
}

fn distance(a: &[f32; 3], b: &[f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn median(mut values: Vec<f32>) -> f32 {
    values.sort_unstable_by(f32::total_cmp);
    values[values.len() / 2]
}
