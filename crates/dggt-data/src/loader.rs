//! The training data stream: samples drawn by the [`Sampler`], their views decoded and preprocessed by worker
//! threads ahead of the training step that consumes them ([`Prefetcher`]).

use std::sync::Arc;

use crate::error::Result;
use crate::prefetch::Prefetcher;
use crate::preprocess::Preprocess;
use crate::sampler::{Sampler, TrainingSample};
use crate::scene::Scene;
use crate::views::{PreparedView, prepare_view};

/// One training step's data.
#[derive(Debug, Clone)]
pub struct LoadedSample {
    /// The training step this sample belongs to.
    pub step: u64,
    pub sample: TrainingSample,
    /// Frame-major: input frame `i`, camera `c` is at `i * cameras + c`.
    pub inputs: Vec<PreparedView>,
    /// Frame-major, like `inputs`.
    pub targets: Vec<PreparedView>,
}

/// How many threads decode and how many samples may wait decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoaderOptions {
    pub workers: usize,
    /// Samples loaded or loading at once; about twice `workers` keeps every worker busy.
    pub capacity: usize,
}

impl Default for LoaderOptions {
    fn default() -> Self {
        Self { workers: 2, capacity: 4 }
    }
}

/// Decodes the views of one sample.
pub fn load_sample(scene: &Scene, preprocess: &Preprocess, step: u64, sample: TrainingSample) -> Result<LoadedSample> {
    let load = |frames: &[usize]| -> Result<Vec<PreparedView>> {
        frames
            .iter()
            .flat_map(|&frame| sample.cameras.iter().map(move |&camera| (frame, camera)))
            .map(|(frame, camera)| prepare_view(scene, frame, camera, preprocess))
            .collect()
    };
    let inputs = load(&sample.input_frames)?;
    let targets = load(&sample.target_frames)?;
    Ok(LoadedSample { step, sample, inputs, targets })
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
    Prefetcher::new(jobs, options.workers, options.capacity, move |(step, sample)| {
        load_sample(&scene, &preprocess, step, sample)
    })
}
