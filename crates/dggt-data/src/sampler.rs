//! Which frames and cameras one training step sees.
//!
//! DGGT trains on `N` unposed input frames and `2N` target frames rendered from the predicted scene. The
//! inputs come from a short window of the log so that the scene barely changes between them; the targets lie
//! between and just around the inputs, so the model is supervised on novel timestamps it has to interpolate.
//!
//! One step is drawn as follows (all choices uniform):
//!
//! 1. a window of `window` consecutive frames lying inside the log;
//! 2. `N` in `min_inputs..=max_inputs`;
//! 3. `N` distinct frames of the window, sorted. There is no minimum spread: every `N`-subset of the window is
//!    equally likely, so the model sees tightly clustered inputs as well as inputs spanning the whole window.
//!    Frames within `window - 1` of either end of the log are covered by fewer windows and so drawn less often;
//! 4. `targets_per_input · N` targets from the *target range* `[first input - target_margin, last input +
//!    target_margin]`, clipped to the log. Targets are distinct whenever the range has enough frames: frames
//!    that are not inputs are taken first, then input frames fill the remaining places. When the range is
//!    smaller than the number of targets, the whole range is taken and then drawn again, without replacement
//!    within each round, so every frame of the range occurs as often as any other, give or take one.
//!    Targets are sorted.
//!
//! Every view of a step uses the same cameras: the configured ones in the configured order, or all of them.
//!
//! Held-out frames (`held_out`, for validation on frames training never sees) are taken out of the log first:
//! the rules above then run on the frames that remain, so a window counts remaining frames and no input or
//! target is ever a held-out frame. Without held-out frames every sample is what it was before they existed.
//!
//! Reproducibility: [`Sampler::sample_at`] derives a generator from `(seed, step)` alone, so step `k` of a run
//! can be reproduced, or training resumed at step `k`, without replaying steps `0..k`. The generator is
//! xoshiro256++ (a fixed algorithm, unlike `StdRng`), so samples are stable for a given `rand` version, which
//! `Cargo.lock` pins.

use rand::rngs::Xoshiro256PlusPlus;
use rand::seq::index;
use rand::{Rng, RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::error::{DataError, Result};
use crate::random::{GOLDEN_GAMMA, splitmix64};

/// How training steps draw their frames and cameras. Missing fields take their defaults.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SamplerConfig {
    /// Fewest input frames per step.
    pub min_inputs: usize,
    /// Most input frames per step.
    pub max_inputs: usize,
    /// Consecutive frames the inputs of one step are drawn from (the paper's 20-frame window).
    pub window: usize,
    /// Target frames per input frame.
    pub targets_per_input: usize,
    /// Frames before the first input and after the last one that targets may also come from.
    pub target_margin: usize,
    /// Camera positions in the scene used for every view, in this order; empty means all cameras.
    pub cameras: Vec<usize>,
    /// Frame positions no step draws, as input or target: held out for validation.
    pub held_out: Vec<usize>,
}

impl Default for SamplerConfig {
    fn default() -> Self {
        Self {
            min_inputs: 4,
            max_inputs: 8,
            window: 20,
            targets_per_input: 2,
            target_margin: 1,
            cameras: Vec::new(),
            held_out: Vec::new(),
        }
    }
}

impl SamplerConfig {
    /// Checks the counts alone (`1 <= min_inputs <= max_inputs <= window`, `targets_per_input >= 1`), which need
    /// no log: a configuration check, so that a wrong count is reported once, before any work, rather than as
    /// every sample failing to load.
    pub fn check_counts(&self) -> Result<()> {
        let fail = |message: String| Err(DataError::Config(format!("sampler: {message}")));
        if self.min_inputs == 0 {
            return fail("min_inputs must be at least 1".into());
        }
        if self.min_inputs > self.max_inputs {
            return fail(format!("min_inputs ({}) exceeds max_inputs ({})", self.min_inputs, self.max_inputs));
        }
        if self.window < self.max_inputs {
            return fail(format!(
                "a window of {} frames cannot hold max_inputs = {} distinct input frames: give a window of at least \
                 {} frames, or fewer inputs",
                self.window, self.max_inputs, self.max_inputs
            ));
        }
        if self.targets_per_input == 0 {
            return fail("targets_per_input must be at least 1".into());
        }
        Ok(())
    }

    /// Checks the settings against a log of `frame_count` frames seen by `camera_count` cameras.
    pub fn validate(&self, frame_count: usize, camera_count: usize) -> Result<()> {
        let fail = |message: String| Err(DataError::Config(format!("sampler: {message}")));
        self.check_counts()?;
        if let Some(outside) = self.held_out.iter().find(|&&f| f >= frame_count) {
            return fail(format!("held-out frame {outside} does not exist; the log has {frame_count} frames"));
        }
        let remaining = self.remaining_frames(frame_count).len();
        if self.window > remaining {
            return fail(format!(
                "the window of {} frames is longer than the log ({frame_count} frames, {remaining} of them not held out)",
                self.window
            ));
        }
        if camera_count == 0 {
            return fail("the scene has no cameras".into());
        }
        for (i, &camera) in self.cameras.iter().enumerate() {
            if camera >= camera_count {
                return fail(format!("camera position {camera} does not exist; the scene has {camera_count} cameras"));
            }
            if self.cameras[..i].contains(&camera) {
                return fail(format!("camera position {camera} is listed twice"));
            }
        }
        Ok(())
    }
}

impl SamplerConfig {
    /// The frames of a log of `frame_count` that steps draw from: every one not held out, in order.
    fn remaining_frames(&self, frame_count: usize) -> Vec<usize> {
        (0..frame_count).filter(|f| !self.held_out.contains(f)).collect()
    }
}

/// The views of one training step, as positions into [`Scene::frames`](crate::Scene::frames) and
/// [`Scene::cameras`](crate::Scene::cameras). Every listed frame is seen by every listed camera.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrainingSample {
    /// Sorted, distinct, all inside one window.
    pub input_frames: Vec<usize>,
    /// Sorted; `targets_per_input` per input; distinct when the target range allows it.
    pub target_frames: Vec<usize>,
    pub cameras: Vec<usize>,
}

/// Draws [`TrainingSample`]s for one log, following the module's rules.
#[derive(Debug, Clone)]
pub struct Sampler {
    config: SamplerConfig,
    /// The frames steps draw from (the log's, less the held-out ones); the rules run on positions into it.
    frames: Vec<usize>,
    frame_count: usize,
    cameras: Vec<usize>,
}

impl Sampler {
    /// A sampler for a log of `frame_count` frames and `camera_count` cameras; errors when `config` does not fit.
    pub fn new(config: SamplerConfig, frame_count: usize, camera_count: usize) -> Result<Self> {
        config.validate(frame_count, camera_count)?;
        let cameras = if config.cameras.is_empty() { (0..camera_count).collect() } else { config.cameras.clone() };
        let frames = config.remaining_frames(frame_count);
        Ok(Self { frame_count: frames.len(), frames, config, cameras })
    }

    pub fn config(&self) -> &SamplerConfig {
        &self.config
    }

    /// The cameras every sample uses.
    pub fn cameras(&self) -> &[usize] {
        &self.cameras
    }

    /// Draws one sample from `rng`.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> TrainingSample {
        let config = &self.config;
        let window_start = rng.random_range(0..=self.frame_count - config.window);
        let input_count = rng.random_range(config.min_inputs..=config.max_inputs);
        let mut input_frames: Vec<usize> =
            index::sample(rng, config.window, input_count).into_iter().map(|i| window_start + i).collect();
        input_frames.sort_unstable();
        let target_frames = self.draw_targets(&input_frames, rng);
        let in_log = |positions: Vec<usize>| positions.into_iter().map(|p| self.frames[p]).collect();
        TrainingSample {
            input_frames: in_log(input_frames),
            target_frames: in_log(target_frames),
            cameras: self.cameras.clone(),
        }
    }

    /// The sample of training step `step` of the run seeded with `seed`; it depends on `(seed, step)` only.
    pub fn sample_at(&self, seed: u64, step: u64) -> TrainingSample {
        self.sample(&mut step_rng(seed, step))
    }

    /// The samples of steps `0, 1, 2, ...` of the run seeded with `seed`.
    pub fn samples(&self, seed: u64) -> impl Iterator<Item = TrainingSample> + '_ {
        self.samples_from(seed, 0)
    }

    /// The samples of steps `first_step, first_step + 1, ...`: resuming a run without replaying earlier steps.
    pub fn samples_from(&self, seed: u64, first_step: u64) -> impl Iterator<Item = TrainingSample> + '_ {
        (first_step..).map(move |step| self.sample_at(seed, step))
    }

    /// `targets_per_input` targets per input from the target range: non-inputs first, then inputs, then
    /// further rounds over the whole range when it is too small.
    fn draw_targets<R: Rng + ?Sized>(&self, inputs: &[usize], rng: &mut R) -> Vec<usize> {
        let (Some(&first), Some(&last)) = (inputs.first(), inputs.last()) else {
            return Vec::new();
        };
        let margin = self.config.target_margin;
        let range = first.saturating_sub(margin)..=last.saturating_add(margin).min(self.frame_count - 1);
        let wanted = self.config.targets_per_input * inputs.len();
        let others: Vec<usize> = range.clone().filter(|f| inputs.binary_search(f).is_err()).collect();
        let mut targets = Vec::with_capacity(wanted);
        fill_with_distinct(&mut targets, wanted, &others, rng);
        fill_with_distinct(&mut targets, wanted, inputs, rng);
        let whole_range: Vec<usize> = range.collect();
        while targets.len() < wanted {
            fill_with_distinct(&mut targets, wanted, &whole_range, rng);
        }
        targets.sort_unstable();
        targets
    }
}

/// Appends distinct elements of `from`, chosen uniformly, until `into` holds `wanted` or `from` is used up.
fn fill_with_distinct<R: Rng + ?Sized>(into: &mut Vec<usize>, wanted: usize, from: &[usize], rng: &mut R) {
    let count = wanted.saturating_sub(into.len()).min(from.len());
    into.extend(index::sample(rng, from.len(), count).into_iter().map(|i| from[i]));
}

/// The generator of one training step. Its initial state is an injective function of `(seed, step)` (the first
/// two words are bijections of `seed` and of `step`), so no two `(seed, step)` pairs start from the same state.
fn step_rng(seed: u64, step: u64) -> Xoshiro256PlusPlus {
    let words = [seed, step, seed ^ GOLDEN_GAMMA, step ^ GOLDEN_GAMMA].map(splitmix64);
    let mut state = [0u8; 32];
    for (chunk, word) in state.chunks_exact_mut(8).zip(words) {
        chunk.copy_from_slice(&word.to_le_bytes());
    }
    Xoshiro256PlusPlus::from_seed(state)
}

#[cfg(test)]
mod tests {
    use std::collections::{BTreeMap, BTreeSet};

    use proptest::prelude::*;

    use super::*;

    /// Asserts every documented invariant of one sample.
    fn check_invariants(sampler: &Sampler, sample: &TrainingSample) {
        let config = sampler.config();
        let inputs = &sample.input_frames;
        let n = inputs.len();
        assert!((config.min_inputs..=config.max_inputs).contains(&n), "{n} inputs: {sample:?}");
        assert!(inputs.windows(2).all(|w| w[0] < w[1]), "inputs not sorted and distinct: {sample:?}");
        assert!(inputs[n - 1] < sampler.frame_count, "{sample:?}");
        assert!(inputs[n - 1] - inputs[0] < config.window, "inputs span more than one window: {sample:?}");

        let targets = &sample.target_frames;
        assert_eq!(targets.len(), config.targets_per_input * n, "{sample:?}");
        assert!(targets.windows(2).all(|w| w[0] <= w[1]), "targets not sorted: {sample:?}");
        let low = inputs[0].saturating_sub(config.target_margin);
        let high = (inputs[n - 1] + config.target_margin).min(sampler.frame_count - 1);
        assert!(targets.iter().all(|t| (low..=high).contains(t)), "target outside [{low}, {high}]: {sample:?}");

        let range_len = high - low + 1;
        let mut counts = BTreeMap::new();
        for &t in targets {
            *counts.entry(t).or_insert(0usize) += 1;
        }
        if range_len >= targets.len() {
            assert!(counts.values().all(|&c| c == 1), "repeated targets although {range_len} frames: {sample:?}");
            if range_len - n >= targets.len() {
                assert!(targets.iter().all(|t| inputs.binary_search(t).is_err()), "input used as target: {sample:?}");
            } else {
                let non_inputs = targets.iter().filter(|t| inputs.binary_search(t).is_err()).count();
                assert_eq!(non_inputs, range_len - n, "every non-input frame must be a target first: {sample:?}");
            }
        } else {
            assert_eq!(counts.len(), range_len, "every frame of the range is a target: {sample:?}");
            let (min, max) = (counts.values().min().unwrap(), counts.values().max().unwrap());
            assert!(max - min <= 1, "targets repeated unevenly: {sample:?}");
        }
        assert_eq!(sample.cameras, sampler.cameras());
    }

    fn config() -> impl Strategy<Value = (SamplerConfig, usize, usize)> {
        (1usize..6, 0usize..5, 0usize..20, 0usize..40, 1usize..4, 0usize..4, 1usize..5).prop_map(
            |(min_inputs, extra_inputs, extra_window, extra_frames, targets_per_input, target_margin, cameras)| {
                let max_inputs = min_inputs + extra_inputs;
                let window = max_inputs + extra_window;
                let config = SamplerConfig {
                    min_inputs,
                    max_inputs,
                    window,
                    targets_per_input,
                    target_margin,
                    cameras: vec![],
                    held_out: vec![],
                };
                (config, window + extra_frames, cameras)
            },
        )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn samples_satisfy_the_invariants((config, frames, cameras) in config(), seed in any::<u64>()) {
            let sampler = Sampler::new(config, frames, cameras).unwrap();
            for sample in sampler.samples(seed).take(50) {
                check_invariants(&sampler, &sample);
            }
        }
    }

    #[test]
    fn default_matches_the_paper() {
        let config = SamplerConfig::default();
        assert_eq!((config.min_inputs, config.max_inputs, config.window), (4, 8, 20));
        assert_eq!((config.targets_per_input, config.target_margin), (2, 1));
        let sampler = Sampler::new(config, 200, 3).unwrap();
        assert_eq!(sampler.cameras(), [0, 1, 2]);
        for sample in sampler.samples(1).take(2000) {
            check_invariants(&sampler, &sample);
        }
    }

    #[test]
    fn every_count_window_and_frame_occurs() {
        let config = SamplerConfig { max_inputs: 6, window: 6, ..SamplerConfig::default() };
        let sampler = Sampler::new(config, 10, 1).unwrap();
        let mut counts = BTreeSet::new();
        let mut inputs = BTreeSet::new();
        let mut targets = BTreeSet::new();
        let mut starts = BTreeSet::new();
        for sample in sampler.samples(5).take(3000) {
            counts.insert(sample.input_frames.len());
            starts.insert(sample.input_frames[0]);
            inputs.extend(sample.input_frames);
            targets.extend(sample.target_frames);
        }
        assert_eq!(counts, (4..=6).collect());
        assert_eq!(inputs, (0..10).collect());
        assert_eq!(targets, (0..10).collect());
        assert_eq!(starts, (0..=6).collect(), "the first input can be anywhere a window of 6 leaves room for 4 inputs");
    }

    #[test]
    fn a_step_depends_on_seed_and_step_only() {
        let sampler = Sampler::new(SamplerConfig::default(), 100, 2).unwrap();
        let run: Vec<_> = sampler.samples(42).take(100).collect();
        assert_eq!(run[37], sampler.sample_at(42, 37));
        assert_eq!(sampler.samples_from(42, 37).next().unwrap(), run[37]);
        assert_eq!(sampler.samples_from(42, 90).take(10).collect::<Vec<_>>(), run[90..]);
        let distinct: BTreeSet<_> = run.iter().map(|s| (s.input_frames.clone(), s.target_frames.clone())).collect();
        assert!(distinct.len() > 95, "steps should differ: {} distinct of 100", distinct.len());
        let other_seed: Vec<_> = sampler.samples(43).take(100).collect();
        assert_ne!(run, other_seed);
    }

    #[test]
    fn step_samples_are_stable_across_builds() {
        // Resuming a run must reproduce its steps; this pins the generator and the drawing procedure.
        let sampler = Sampler::new(SamplerConfig::default(), 50, 1).unwrap();
        let sample = sampler.sample_at(7, 3);
        assert_eq!(sample.input_frames, vec![13, 14, 15, 16, 22]);
        assert_eq!(sample.target_frames, vec![12, 13, 14, 17, 18, 19, 20, 21, 22, 23]);
    }

    #[test]
    fn small_target_ranges_repeat_frames_evenly() {
        // Five consecutive inputs in a window of five: the target range has 7 frames for 10 targets.
        let config = SamplerConfig { min_inputs: 5, max_inputs: 5, window: 5, ..SamplerConfig::default() };
        let sampler = Sampler::new(config, 30, 1).unwrap();
        for sample in sampler.samples(3).take(200) {
            check_invariants(&sampler, &sample);
            let inputs = &sample.input_frames;
            assert_eq!(inputs[4] - inputs[0], 4);
        }
    }

    #[test]
    fn cameras_follow_the_configuration() {
        let config = SamplerConfig { cameras: vec![2, 0], ..SamplerConfig::default() };
        let sampler = Sampler::new(config, 40, 3).unwrap();
        assert_eq!(sampler.sample_at(0, 0).cameras, vec![2, 0]);
        let single = Sampler::new(SamplerConfig { cameras: vec![1], ..SamplerConfig::default() }, 40, 3).unwrap();
        assert_eq!(single.sample_at(0, 0).cameras, vec![1]);
        let all = Sampler::new(SamplerConfig::default(), 40, 1).unwrap();
        assert_eq!(all.sample_at(0, 0).cameras, vec![0]);
    }

    #[test]
    fn invalid_configurations_are_rejected() {
        let base = SamplerConfig::default();
        let cases = [
            (SamplerConfig { min_inputs: 0, ..base.clone() }, 100, 1, "min_inputs must be at least 1"),
            (SamplerConfig { min_inputs: 9, ..base.clone() }, 100, 1, "exceeds max_inputs"),
            (SamplerConfig { window: 7, ..base.clone() }, 100, 1, "cannot hold"),
            (base.clone(), 19, 1, "longer than the log"),
            (SamplerConfig { targets_per_input: 0, ..base.clone() }, 100, 1, "targets_per_input"),
            (base.clone(), 100, 0, "no cameras"),
            (SamplerConfig { cameras: vec![0, 3], ..base.clone() }, 100, 3, "does not exist"),
            (SamplerConfig { cameras: vec![1, 1], ..base.clone() }, 100, 3, "listed twice"),
        ];
        for (config, frames, cameras, expected) in cases {
            match Sampler::new(config.clone(), frames, cameras) {
                Err(DataError::Config(message)) => assert!(message.contains(expected), "{message}"),
                other => panic!("{config:?} with {frames} frames, {cameras} cameras: {other:?}"),
            }
        }
        assert!(Sampler::new(SamplerConfig { window: 20, ..base }, 20, 1).is_ok(), "a window may cover the log");
    }

    #[test]
    fn configuration_reads_partial_json_and_rejects_unknown_fields() {
        let config: SamplerConfig = serde_json::from_str(r#"{"max_inputs": 6, "cameras": [0, 1]}"#).unwrap();
        assert_eq!(config, SamplerConfig { max_inputs: 6, cameras: vec![0, 1], ..SamplerConfig::default() });
        let round_trip: SamplerConfig = serde_json::from_str(&serde_json::to_string(&config).unwrap()).unwrap();
        assert_eq!(round_trip, config);
        assert!(serde_json::from_str::<SamplerConfig>(r#"{"windows": 10}"#).is_err());
    }

    #[test]
    fn held_out_frames_are_never_drawn_and_the_rest_are() {
        let config = SamplerConfig { window: 8, held_out: vec![2, 6, 10, 14, 18], ..SamplerConfig::default() };
        let sampler = Sampler::new(config.clone(), 20, 1).unwrap();
        let mut drawn = BTreeSet::new();
        for sample in sampler.samples(7).take(400) {
            for frame in sample.input_frames.iter().chain(&sample.target_frames) {
                assert!(!config.held_out.contains(frame), "held-out frame {frame} drawn: {sample:?}");
                drawn.insert(*frame);
            }
            // The window counts remaining frames: 8 of them span at most 11 of the log here (3 held out).
            let inputs = &sample.input_frames;
            assert!(inputs[inputs.len() - 1] - inputs[0] <= 10, "{sample:?}");
        }
        let remaining: BTreeSet<usize> = (0..20).filter(|f| !config.held_out.contains(f)).collect();
        assert_eq!(drawn, remaining);
        let too_many = SamplerConfig { window: 16, ..config.clone() };
        assert!(matches!(Sampler::new(too_many, 20, 1), Err(DataError::Config(m)) if m.contains("not held out")));
        let outside = SamplerConfig { held_out: vec![20], ..config };
        assert!(matches!(Sampler::new(outside, 20, 1), Err(DataError::Config(m)) if m.contains("does not exist")));
    }
}
