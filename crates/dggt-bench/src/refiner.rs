//! The diffusion refiner's cost per frame: a refiner (usually with made-up weights at sd-turbo's size,
//! `dggt_refine::random`) refines made-up frames of a given size, untimed warm-up runs first, and each timed
//! run's wall time (from the frame on the device to the refined frame read back) is returned.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use dggt_model::host::host_f32;
use dggt_refine::{Latent, Refiner, Trace};

use crate::error::BenchError;

/// Whether the refiner attends to a reference view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefinerMode {
    SingleView,
    /// With a reference view: two views through the networks per frame.
    ReferenceView,
}

/// Milliseconds of each of `repeat` runs refining one `height` x `width` frame, after `warmup` untimed runs.
pub fn time_refiner_frames(
    refiner: &Refiner,
    [height, width]: [usize; 2],
    mode: RefinerMode,
    warmup: usize,
    repeat: usize,
    device: &Device,
) -> Result<Vec<f64>, BenchError> {
    let image = || Tensor::<4>::random([1, 3, height, width], Distribution::Uniform(0.0, 1.0), device);
    let (frame, reference) = match mode {
        RefinerMode::SingleView => (image(), None),
        RefinerMode::ReferenceView => (image(), Some(image())),
    };
    let mut times = Vec::with_capacity(repeat);
    for run in 0..warmup + repeat {
        let started = Instant::now();
        let refined = refiner
            .refine(frame.clone(), reference.clone(), Latent::PosteriorMean, &mut Trace::Off)
            .map_err(|source| BenchError::Refine { doing: "refining a frame", source: Box::new(source) })?;
        host_f32(refined, "refined frame")?;
        if run >= warmup {
            times.push(started.elapsed().as_secs_f64() * 1e3);
        }
    }
    Ok(times)
}
