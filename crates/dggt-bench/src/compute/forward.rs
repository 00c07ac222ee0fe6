//! The network's forward pass at scale: timed on a few frame counts and precisions, and the longest input
//! sequence it fits in the device's memory.
//!
//! What runs is the reconstruction's forward ([`forward_chunked`]): the aggregator over all frames, the camera
//! head, and the dense heads DGGT reads (depth, Gaussian, dynamic) a few frames at a time; the point and
//! semantic heads, whose outputs nothing reads, do not run (the release runs both, on every frame at once).
//! Weights are random (a fixed seed): the time does not depend on their values. Images are `[1, S, 3, H, W]`
//! RGB in `[0, 1]`, uniform noise.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use dggt_infer::{MotionPath, Prediction, forward_chunked};
use dggt_model::Dggt;

use super::memory::{DeviceMemory, guarded};
use super::{ComputeOptions, Record, ScaleSpec, timed};
use crate::error::BenchError;
use crate::knobs::Precision;
use crate::precision::{PrecisionUnsupported, cast_model, precision_support};
use crate::stages::settle;

const HEADS_NOTE: &str = "camera, depth, Gaussian and dynamic heads (the point and semantic heads, which nothing \
                          reads, skipped)";

/// `forward/{S}/{precision}` for every frame count and precision of the scale.
pub fn forward_records(
    options: &ComputeOptions,
    spec: &ScaleSpec,
    device: &Device,
    keep: &mut impl FnMut(Record),
) -> Result<(), BenchError> {
    let note = format!("{HEADS_NOTE}; dense heads {} frames at a time", options.chunk_frames);
    per_size("forward", &note, options, spec, device, keep, |model, images| {
        run_forward(model, images, options.chunk_frames)
    })
}

/// `aggregator/{S}/{precision}`: the aggregator alone (the DINO encoder and the alternating attention), the
/// part of `forward/{S}/{precision}` that is not the heads.
pub fn aggregator_records(
    options: &ComputeOptions,
    spec: &ScaleSpec,
    device: &Device,
    keep: &mut impl FnMut(Record),
) -> Result<(), BenchError> {
    per_size("aggregator", "", options, spec, device, keep, |model, images| {
        let output = model.aggregator.forward(images)?;
        let last = output.output_list.last().cloned();
        settle(&last.ok_or_else(|| BenchError::Missing("model: no aggregator layer"))?.sum())
    })
}

/// `{name}/{S}/{precision}` timed (with `note`) for every frame count and precision of the scale; a precision
/// the device cannot compute in is recorded as failed.
fn per_size(
    name: &str,
    note: &str,
    options: &ComputeOptions,
    spec: &ScaleSpec,
    device: &Device,
    keep: &mut impl FnMut(Record),
    mut run: impl FnMut(&Dggt, Tensor<5>) -> Result<(), BenchError>,
) -> Result<(), BenchError> {
    let network = Network::new(spec, options.seed, device)?;
    for &precision in &options.precisions {
        let model = network.in_precision(precision);
        for &frames in &spec.forward_frames {
            let key = format!("{name}/{frames}/{precision}");
            match &model {
                Ok(model) => {
                    let images = network.images(frames);
                    keep(timed(key, options, device, || run(model, images.clone())).with_note(note));
                }
                Err(reason) => keep(Record::failed(key, reason)),
            }
        }
    }
    Ok(())
}

/// `longest/{precision}`: the most frames one forward pass completes with, by doubling from the scale's start
/// and then bisecting to within a quarter of the start, within the options' time budget.
pub fn longest_records(
    options: &ComputeOptions,
    spec: &ScaleSpec,
    device: &Device,
    keep: &mut impl FnMut(Record),
) -> Result<(), BenchError> {
    let network = Network::new(spec, options.seed, device)?;
    for &precision in &options.longest_precisions {
        let key = format!("longest/{precision}");
        let model = match network.in_precision(precision) {
            Ok(model) => model,
            Err(reason) => {
                keep(Record::failed(key, reason));
                continue;
            }
        };
        let fits = |frames: usize| {
            let _memory = DeviceMemory::start(device);
            let fitted = guarded(|| run_forward(&model, network.images(frames), options.chunk_frames));
            if let Err(error) = &fitted {
                tracing::info!(frames, %error, "the forward pass does not fit");
            }
            fitted.is_ok()
        };
        let (start, max) = options.longest_range.unwrap_or((spec.longest_start, spec.longest_max));
        let search = search_longest(start, max, options.longest_budget_s, fits);
        device.memory_cleanup();
        let note = format!("{HEADS_NOTE}; {}", search.note);
        keep(Record { frames: Some(search.frames), ..Record::new(key) }.with_note(note));
    }
    Ok(())
}

/// The network once in f32, cast per precision.
struct Network {
    model: Dggt,
    spec: ScaleSpec,
    device: Device,
}

impl Network {
    fn new(spec: &ScaleSpec, seed: u64, device: &Device) -> Result<Self, BenchError> {
        let model = dggt_infer::fresh_model(&spec.model, None, seed, device)?;
        Ok(Self { model, spec: spec.clone(), device: device.clone() })
    }

    /// The network computing in `precision`, or why the device cannot.
    fn in_precision(&self, precision: Precision) -> Result<Dggt, PrecisionUnsupported> {
        precision_support(&self.device, precision)?;
        Ok(if precision == Precision::F32 { self.model.clone() } else { cast_model(&self.model, precision) })
    }

    fn images(&self, frames: usize) -> Tensor<5> {
        let (height, width) = (self.spec.image.height as usize, self.spec.image.width as usize);
        Tensor::random([1, frames, 3, height, width], Distribution::Uniform(0.0, 1.0), &self.device)
    }
}

/// One forward pass, blocking until every output is computed.
fn run_forward(model: &Dggt, images: Tensor<5>, chunk: usize) -> Result<(), BenchError> {
    let prediction = forward_chunked(model, images, chunk, MotionPath::Always)?;
    settle(&everything(&prediction))
}

/// One value that depends on every output of `prediction`, so reading it waits for all of them.
fn everything(prediction: &Prediction) -> Tensor<1> {
    let mut total = prediction.pose_encoding().sum() + prediction.depth.clone().sum();
    if let Some(logit) = &prediction.dynamic_logit {
        total = total + logit.clone().sum();
    }
    if let Some(maps) = &prediction.gaussians {
        total = total + maps.rgb.clone().sum() + maps.opacity.clone().sum() + maps.scale.clone().sum();
        total = total + maps.rotation.clone().sum() + maps.lifespan.clone().sum();
    }
    total
}

/// The answer of a longest-sequence search.
#[derive(Debug, Clone, PartialEq)]
pub struct LongestSearch {
    /// The most frames seen to fit (0 when not even the fewest tried did).
    pub frames: usize,
    pub note: String,
}

/// Doubles from `start` while `fits`, then bisects between the last fit and the first failure to within a
/// quarter of `start`; never tries more than `max`, stops trying once `budget_s` seconds have passed.
pub fn search_longest(start: usize, max: usize, budget_s: f64, mut fits: impl FnMut(usize) -> bool) -> LongestSearch {
    let started = Instant::now();
    let out_of_time = || started.elapsed().as_secs_f64() > budget_s;
    let mut tried = Vec::new();
    let (mut fitted, mut failed) = (0, None);
    let mut frames = start.max(1).min(max);
    loop {
        let ok = fits(frames);
        tried.push(format!("{frames}{}", if ok { "" } else { " (failed)" }));
        if !ok {
            failed = Some(frames);
            break;
        }
        fitted = frames;
        if frames >= max || out_of_time() {
            break;
        }
        frames = (frames * 2).min(max);
    }
    let resolution = (start / 4).max(1);
    while let Some(upper) = failed {
        if upper - fitted <= resolution || out_of_time() {
            break;
        }
        let middle = fitted + (upper - fitted) / 2;
        let ok = fits(middle);
        tried.push(format!("{middle}{}", if ok { "" } else { " (failed)" }));
        if ok { fitted = middle } else { failed = Some(middle) }
    }
    let bound = match failed {
        Some(upper) => format!("{upper} frames did not fit"),
        None if fitted >= max => format!("stopped at the cap of {max} frames"),
        None => "stopped by the time budget".into(),
    };
    let budget = if out_of_time() { format!("; the {budget_s:.0} s budget ran out") } else { String::new() };
    LongestSearch { frames: fitted, note: format!("{bound}; tried {}{budget}", tried.join(", ")) }
}

#[cfg(test)]
mod tests {
    use super::search_longest;

    #[test]
    fn the_search_finds_the_limit_to_within_a_quarter_of_the_start() {
        let mut tries = Vec::new();
        let search = search_longest(16, 1024, 1e9, |frames| {
            tries.push(frames);
            frames <= 75
        });
        assert!((72..=75).contains(&search.frames), "{search:?}");
        assert_eq!(&tries[..4], &[16, 32, 64, 128]);
        assert!(search.note.contains("did not fit"), "{}", search.note);
    }

    #[test]
    fn the_search_stops_at_the_cap_and_reports_nothing_fitting() {
        assert_eq!(search_longest(2, 8, 1e9, |_| true).frames, 8);
        let none = search_longest(16, 64, 1e9, |_| false);
        assert_eq!(none.frames, 0, "{none:?}");
    }
}
