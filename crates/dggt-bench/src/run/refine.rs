//! The diffusion refiner's part of a row: every render refined one frame at a time, timed over the
//! repetitions. Only runs when the sweep was given a refiner.

use std::time::Instant;

use burn::tensor::Device;
use dggt_refine::{Latent, Refiner, frame_from_interleaved, frame_to_interleaved};

use super::measure::{RowRun, median};
use crate::error::BenchError;

/// Refines every render of `run` (`[H, W, 3]` at `run.size`, each attending to its reference view when the
/// run has them) `repeat` times: the median milliseconds of a pass, and the refined images.
pub(super) fn refine_renders(
    refiner: &Refiner,
    latent: Latent,
    run: &RowRun,
    repeat: usize,
    device: &Device,
) -> Result<(f64, Vec<Vec<f32>>), BenchError> {
    let refine_error = |source| BenchError::Refine { doing: "refining a render", source: Box::new(source) };
    let (h, w) = (run.size.height as usize, run.size.width as usize);
    let mut times = Vec::new();
    let mut refined = Vec::new();
    for _ in 0..repeat.max(1) {
        let started = Instant::now();
        refined = run
            .renders
            .iter()
            .enumerate()
            .map(|(i, rgb)| {
                let frame = frame_from_interleaved(rgb, h, w, device)?;
                let reference = run.references.get(i).map(|r| frame_from_interleaved(r, h, w, device)).transpose()?;
                frame_to_interleaved(&refiner.refine_frames(frame, reference, latent, 1, |_| ())?, 0)
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(refine_error)?;
        times.push(started.elapsed().as_secs_f64() * 1e3);
    }
    Ok((median(times), refined))
}
