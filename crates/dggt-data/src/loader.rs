//! The training data stream: samples drawn by the [`Sampler`] (across the scenes of a [`DatasetIndex`], by the
//! [`SceneMix`]), their views decoded and preprocessed by worker threads ahead of the training step that
//! consumes them ([`Prefetcher`]).
//!
//! A sample of a dataset run opens only its scene's window of frames, in the worker, so memory stays flat
//! however many scenes there are. When a sample fails to load (a corrupt JPEG, a truncated mask), the worker
//! draws a replacement scene for it (a function of the seed, the sample and the attempt, so resuming draws
//! the same) and records the failure, naming the file, in the sample it finally delivers; after
//! [`MAX_LOAD_ATTEMPTS`] failures in a row the sample is an error.

use std::sync::Arc;

use crate::decoded::DecodedViews;
use crate::error::{DataError, Result};
use crate::index::DatasetIndex;
use crate::mix::SceneMix;
use crate::prefetch::Prefetcher;
use crate::preprocess::Preprocess;
use crate::sampler::{Sampler, SamplerConfig, TrainingSample};
use crate::scene::Scene;
use crate::views::{PreparedView, prepare_view_cached};

/// Loads tried for one sample before it is an error.
pub const MAX_LOAD_ATTEMPTS: u32 = 4;

/// One training step's data.
#[derive(Debug, Clone)]
pub struct LoadedSample {
    /// The training step this sample belongs to.
    pub step: u64,
    /// The scene the views come from (for a dataset run, the window of frames the sample spans).
    pub scene: Arc<Scene>,
    /// Positions in `scene`.
    pub sample: TrainingSample,
    /// Frame-major: input frame `i`, camera `c` is at `i * cameras + c`.
    pub inputs: Vec<PreparedView>,
    /// Frame-major, like `inputs`.
    pub targets: Vec<PreparedView>,
    /// Loads that failed before this one succeeded, each naming the file at fault.
    pub failures: Vec<String>,
}

/// How many threads decode, how many samples may wait decoded, and how much decoded pixels are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoaderOptions {
    pub workers: usize,
    /// Samples loaded or loading at once; about twice `workers` keeps every worker busy.
    pub capacity: usize,
    /// Bytes of decoded, preprocessed images and masks kept between samples ([`DecodedViews`]); 0 decodes every
    /// view each time it is drawn.
    pub decoded_cache_bytes: usize,
}

impl LoaderOptions {
    /// The default cache: 512 MiB, every view of a few hundred frames of six cameras at the release's 518 x 294.
    pub const DEFAULT_DECODED_CACHE_BYTES: usize = 512 << 20;
}

impl Default for LoaderOptions {
    fn default() -> Self {
        Self { workers: 2, capacity: 4, decoded_cache_bytes: Self::DEFAULT_DECODED_CACHE_BYTES }
    }
}

/// Decodes the views of one sample.
pub fn load_sample(
    scene: &Arc<Scene>,
    preprocess: &Preprocess,
    step: u64,
    sample: TrainingSample,
) -> Result<LoadedSample> {
    load_sample_cached(scene, preprocess, step, sample, &DecodedViews::none())
}

/// [`load_sample`], with the images and masks `cache` keeps.
fn load_sample_cached(
    scene: &Arc<Scene>,
    preprocess: &Preprocess,
    step: u64,
    sample: TrainingSample,
    cache: &DecodedViews,
) -> Result<LoadedSample> {
    let load = |frames: &[usize]| -> Result<Vec<PreparedView>> {
        frames
            .iter()
            .flat_map(|&frame| sample.cameras.iter().map(move |&camera| (frame, camera)))
            .map(|(frame, camera)| prepare_view_cached(scene, frame, camera, preprocess, cache))
            .collect()
    };
    let inputs = load(&sample.input_frames)?;
    let targets = load(&sample.target_frames)?;
    Ok(LoadedSample { step, scene: scene.clone(), sample, inputs, targets, failures: Vec::new() })
}

/// Where a dataset run's samples come from: the indexed scenes, which scene each sample draws, and how frames
/// are drawn within it.
#[derive(Debug, Clone)]
pub struct DatasetSampling {
    pub index: Arc<DatasetIndex>,
    pub mix: SceneMix,
    pub sampler: SamplerConfig,
    pub seed: u64,
}

impl DatasetSampling {
    /// Sample `sample`: its scene window opened and its views decoded (or taken from `cache`), replacing scenes
    /// that fail to load.
    pub fn load(&self, preprocess: &Preprocess, sample: u64, cache: &DecodedViews) -> Result<LoadedSample> {
        let (mut failures, mut failed) = (Vec::new(), Vec::new());
        for attempt in 0..MAX_LOAD_ATTEMPTS {
            let scene = match attempt {
                0 => self.mix.scene_at(sample),
                _ => self.mix.replacement(sample, attempt, &failed),
            };
            match self.load_from(scene, preprocess, sample, attempt, cache) {
                Ok(mut loaded) => {
                    loaded.failures = failures;
                    return Ok(loaded);
                }
                Err(error) => {
                    tracing::warn!(sample, scene = %self.index.scenes[scene].name, %error, "sample skipped");
                    failures.push(error.to_string());
                    failed.push(scene);
                }
            }
        }
        Err(DataError::Worker(format!("sample {sample}: {}", self.failed_scenes(&failed, &failures))))
    }

    /// The scenes of failed loads (`scenes[i]` gave `errors[i]`) in words, each scene named once with its first
    /// error: a scene drawn again as its own replacement is one scene, not several.
    fn failed_scenes(&self, scenes: &[usize], errors: &[String]) -> String {
        let mut distinct: Vec<(usize, &str)> = Vec::new();
        for (&scene, error) in scenes.iter().zip(errors) {
            if !distinct.iter().any(|(seen, _)| *seen == scene) {
                distinct.push((scene, error));
            }
        }
        let count = match distinct.len() {
            1 => "1 scene".to_string(),
            n => format!("{n} scenes"),
        };
        let listed: Vec<String> =
            distinct.iter().map(|(scene, error)| format!("{}: {error}", self.index.scenes[*scene].name)).collect();
        format!("{count} failed to load in {} attempts: {}", scenes.len(), listed.join("; "))
    }

    /// Draws the frames of sample `sample` in scene `scene`, opens the window they span and decodes them.
    fn load_from(
        &self,
        scene: usize,
        preprocess: &Preprocess,
        sample: u64,
        attempt: u32,
        cache: &DecodedViews,
    ) -> Result<LoadedSample> {
        let indexed = &self.index.scenes[scene];
        let camera_positions: Vec<usize> = (0..indexed.cameras.len()).collect();
        let config = SamplerConfig { cameras: Vec::new(), ..self.sampler.clone() };
        let sampler = Sampler::new(config, indexed.frame_count(), camera_positions.len())
            .map_err(|e| DataError::Config(format!("{}: {e}", indexed.name)))?;
        let drawn = sampler.sample_at(self.seed ^ attempt as u64, sample);
        let frames = drawn.input_frames.iter().chain(&drawn.target_frames);
        let (first, last) = (*frames.clone().min().expect("inputs"), *frames.max().expect("inputs"));
        let window = Arc::new(indexed.open(first..last + 1)?);
        let shift = |frames: &[usize]| frames.iter().map(|f| f - first).collect();
        let in_window = TrainingSample {
            input_frames: shift(&drawn.input_frames),
            target_frames: shift(&drawn.target_frames),
            cameras: drawn.cameras,
        };
        load_sample_cached(&window, preprocess, sample, in_window, cache)
    }
}

/// The stream of a dataset run's samples at the positions `samples` lists (`first..` for a run in one process;
/// a rank of several takes its share of every step), decoded ahead of time. Sample `k` is always the same, so a
/// resumed run sees what the uninterrupted one would.
pub fn dataset_stream(
    sampling: DatasetSampling,
    preprocess: Preprocess,
    samples: impl Iterator<Item = u64> + Send + 'static,
    options: LoaderOptions,
) -> Result<Prefetcher<LoadedSample>> {
    preprocess.validate()?;
    let cache = DecodedViews::new(options.decoded_cache_bytes);
    Prefetcher::new(samples, options.workers, options.capacity, move |sample| {
        sampling.load(&preprocess, sample, &cache)
    })
}

/// The endless stream of training samples of the run seeded with `seed`, from step `first_step` on, decoded
/// ahead of time. Step `k` always gets the same sample, so a resumed run sees what the uninterrupted one would.
pub fn training_stream(
    scene: Arc<Scene>,
    sampler: Sampler,
    preprocess: Preprocess,
    seed: u64,
    first_step: u64,
    options: LoaderOptions,
) -> Result<Prefetcher<LoadedSample>> {
    preprocess.validate()?;
    let jobs = (first_step..).map(move |step| (step, sampler.sample_at(seed, step)));
    let cache = DecodedViews::new(options.decoded_cache_bytes);
    Prefetcher::new(jobs, options.workers, options.capacity, move |(step, sample)| {
        load_sample_cached(&scene, &preprocess, step, sample, &cache)
    })
}
