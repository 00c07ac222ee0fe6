//! Which scene each training sample draws, across datasets.
//!
//! Samples are grouped in epochs. In one epoch a dataset of `n` training scenes and weight `w` is drawn
//! `max(1, round(w · n))` times: whole rounds over its scenes, then a part round without replacement, so no
//! scene repeats before every scene of its dataset came once. The draws of all datasets are then shuffled
//! together. Sample `k` lies in epoch `k / L` (`L` the epoch length) at position `k % L`, and an epoch's order is
//! a function of `(seed, epoch)` alone, so any sample is found again without replaying earlier ones and a
//! resumed run draws what the uninterrupted one would.

use crate::error::{DataError, Result};
use crate::index::{DatasetIndex, Split};
use crate::random::{GOLDEN_GAMMA, SplitMix64, splitmix64};

/// The scene draws of a run.
#[derive(Debug, Clone)]
pub struct SceneMix {
    /// Per dataset: positions of its training scenes in the index, and its draws per epoch.
    pools: Vec<(Vec<usize>, usize)>,
    epoch_len: usize,
    seed: u64,
}

impl SceneMix {
    /// The mix of the training scenes of `index`, seeded with `seed`; an error when there are none.
    pub fn new(index: &DatasetIndex, seed: u64) -> Result<Self> {
        let pools: Vec<(Vec<usize>, usize)> = index
            .specs
            .iter()
            .enumerate()
            .filter_map(|(dataset, spec)| {
                let scenes: Vec<usize> = (0..index.scenes.len())
                    .filter(|&i| index.scenes[i].dataset == dataset && index.scenes[i].split == Split::Train)
                    .collect();
                let draws = ((spec.weight * scenes.len() as f64).round() as usize).max(1);
                (!scenes.is_empty()).then_some((scenes, draws))
            })
            .collect();
        let epoch_len = pools.iter().map(|(_, draws)| draws).sum();
        if epoch_len == 0 {
            return Err(DataError::Config("no training scene: every scene is held out or excluded".into()));
        }
        Ok(Self { pools, epoch_len, seed })
    }

    /// Samples per epoch.
    pub fn epoch_len(&self) -> usize {
        self.epoch_len
    }

    /// The scene positions of epoch `epoch`, in draw order.
    pub fn epoch(&self, epoch: u64) -> Vec<usize> {
        let mut rng = SplitMix64::new(splitmix64(self.seed ^ GOLDEN_GAMMA) ^ splitmix64(epoch));
        let mut draws = Vec::with_capacity(self.epoch_len);
        for (scenes, count) in &self.pools {
            let mut round = scenes.clone();
            let mut left = *count;
            while left > 0 {
                rng.shuffle(&mut round);
                let take = left.min(round.len());
                draws.extend_from_slice(&round[..take]);
                left -= take;
            }
        }
        rng.shuffle(&mut draws);
        draws
    }

    /// The scene of sample `sample`.
    pub fn scene_at(&self, sample: u64) -> usize {
        let len = self.epoch_len as u64;
        self.epoch(sample / len)[(sample % len) as usize]
    }

    /// A replacement scene for sample `sample` after `attempt` failed loads (`attempt >= 1`) of the scenes in
    /// `failed`: uniform over the other training scenes (over all when none is left), a function of `(seed,
    /// sample, attempt, failed)`.
    pub fn replacement(&self, sample: u64, attempt: u32, failed: &[usize]) -> usize {
        let mut rng = SplitMix64::new(splitmix64(self.seed) ^ splitmix64(sample) ^ splitmix64(attempt as u64));
        let all: Vec<usize> = self.pools.iter().flat_map(|(scenes, _)| scenes.iter().copied()).collect();
        let others: Vec<usize> = all.iter().copied().filter(|s| !failed.contains(s)).collect();
        let pool = if others.is_empty() { &all } else { &others };
        pool[rng.below(pool.len())]
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::index::{DatasetSpec, IndexedScene};
    use crate::open::LogLayout;

    fn index(datasets: &[(usize, f64)]) -> DatasetIndex {
        let specs = datasets.iter().map(|&(_, weight)| DatasetSpec { weight, ..DatasetSpec::default() }).collect();
        let scenes = datasets
            .iter()
            .enumerate()
            .flat_map(|(dataset, &(count, _))| {
                (0..count).map(move |i| IndexedScene {
                    dataset,
                    name: format!("{dataset}/{i}"),
                    root: format!("/data/{dataset}/{i}").into(),
                    layout: LogLayout::Waymo,
                    frames: 0..20,
                    cameras: vec![0],
                    split: if i == 0 && count > 3 { Split::Validation } else { Split::Train },
                    modified_s: 0,
                })
            })
            .collect();
        DatasetIndex { specs, seed: 0, scenes, excluded: Vec::new() }
    }

    #[test]
    fn an_epoch_draws_each_dataset_by_weight_without_early_repeats() {
        // Dataset 0: 5 scenes, one held out, weight 1; dataset 1: 3 scenes, weight 2.5 -> 8 draws.
        let index = index(&[(5, 1.0), (3, 2.5)]);
        let mix = SceneMix::new(&index, 7).unwrap();
        assert_eq!(mix.epoch_len(), 4 + 8);
        for epoch in 0..5 {
            let draws = mix.epoch(epoch);
            let mut counts = BTreeMap::new();
            for &scene in &draws {
                *counts.entry(scene).or_insert(0) += 1;
                assert_eq!(index.scenes[scene].split, Split::Train, "held-out scenes are never drawn");
            }
            assert!((1..5).all(|s| counts[&s] == 1), "dataset 0: every training scene once: {counts:?}");
            let second: Vec<usize> = (5..8).map(|s| counts[&s]).collect();
            assert_eq!(second.iter().sum::<usize>(), 8);
            assert!(second.iter().all(|&c| c == 2 || c == 3), "whole rounds, then a part round: {second:?}");
        }
        assert_ne!(mix.epoch(0), mix.epoch(1), "epochs are shuffled anew");
    }

    #[test]
    fn draws_depend_on_seed_and_sample_only() {
        let index = index(&[(6, 1.0), (4, 1.0)]);
        let (a, b) = (SceneMix::new(&index, 3).unwrap(), SceneMix::new(&index, 3).unwrap());
        let epoch = a.epoch(2);
        for k in 0..a.epoch_len() as u64 {
            assert_eq!(a.scene_at(2 * a.epoch_len() as u64 + k), epoch[k as usize]);
            assert_eq!(a.scene_at(k), b.scene_at(k));
        }
        assert_ne!((0..30).map(|k| a.scene_at(k)).collect::<Vec<_>>(), {
            let c = SceneMix::new(&index, 4).unwrap();
            (0..30).map(|k| c.scene_at(k)).collect::<Vec<_>>()
        });
        let failed = [a.scene_at(5)];
        for attempt in 1..4 {
            let replacement = a.replacement(5, attempt, &failed);
            assert_eq!(index.scenes[replacement].split, Split::Train);
            assert_ne!(replacement, failed[0], "a scene that failed is not drawn again");
        }
    }

    #[test]
    fn a_run_without_training_scenes_is_an_error() {
        let mut index = index(&[(2, 1.0)]);
        index.scenes.iter_mut().for_each(|s| s.split = Split::Validation);
        assert!(SceneMix::new(&index, 0).unwrap_err().to_string().contains("no training scene"));
    }
}
