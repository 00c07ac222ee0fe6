//! The port's value of one reference output and how it is compared: elementwise on the largest absolute
//! difference (optionally on a mask of the elements, or through a map applied to both sides), or, for rendered
//! images, pixel by pixel (see [`RENDER_PIXEL_FRACTION`]). Comparisons are made in `f32`.

use burn::tensor::Tensor;

use crate::report::{ParityRow, Status};
use crate::tolerance::NETWORK;
use crate::vectors::HostTensor;

/// The fraction of a rendered image's pixels that must be within tolerance.
pub const RENDER_PIXEL_FRACTION: f64 = 0.999;

/// The port's value of a reference output.
pub(super) struct Actual {
    pub tensor: HostTensor,
    /// Only these elements are compared (all when `None`).
    pub mask: Option<Vec<bool>>,
    /// Both sides pass through this before comparing.
    pub map: Option<fn(f32) -> f32>,
    pub note: Option<&'static str>,
    /// Compared as an image with this many channels per pixel (see [`RENDER_PIXEL_FRACTION`]).
    pub pixel_channels: Option<usize>,
}

pub(super) fn dense<const D: usize>(tensor: Tensor<D>) -> Actual {
    host(HostTensor::from_tensor(tensor))
}

pub(super) fn host(tensor: HostTensor) -> Actual {
    Actual { tensor, mask: None, map: None, note: None, pixel_channels: None }
}

/// A rendered image, compared pixel by pixel.
pub(super) fn image<const D: usize>(tensor: Tensor<D>, channels: usize) -> Actual {
    Actual { pixel_channels: Some(channels), ..dense(tensor) }
}

/// The largest absolute difference, the largest reference magnitude and whether the port's values are finite
/// (where they differ from the reference's), over the compared elements of both sides after the map.
struct Differences {
    max_abs: f32,
    max_reference: f32,
    finite: bool,
}

fn differences(actual: &Actual, reference: &HostTensor) -> Differences {
    let map = actual.map.unwrap_or(|v| v);
    let compared = |i: usize| actual.mask.as_ref().is_none_or(|mask| mask[i]);
    let mut found = Differences { max_abs: 0.0, max_reference: 0.0, finite: true };
    let pairs = actual.tensor.values.iter().zip(&reference.values).enumerate();
    for (_, (&a, &r)) in pairs.filter(|(i, _)| compared(*i)) {
        let (a, r) = (map(a), map(r));
        found.finite &= a.is_finite() || a == r;
        found.max_reference = found.max_reference.max(r.abs());
        let difference = if a == r { 0.0 } else { (a - r).abs() };
        found.max_abs = if difference.is_nan() { f32::INFINITY } else { found.max_abs.max(difference) };
    }
    found
}

/// Whether enough pixels are within `tolerance` on every channel, and the note saying how many.
fn pixels_within(actual: &Actual, reference: &HostTensor, channels: usize, tolerance: f32) -> (bool, String) {
    let within = |(a, r): (&[f32], &[f32])| a.iter().zip(r).all(|(a, r)| a == r || (a - r).abs() <= tolerance);
    let pixels = actual.tensor.values.chunks(channels).zip(reference.values.chunks(channels));
    let total = actual.tensor.values.len() / channels;
    let good = pixels.filter(|&pair| within(pair)).count();
    let fraction = good as f64 / total.max(1) as f64;
    let note = if good == total {
        format!("all {total} pixels within tolerance")
    } else {
        format!(
            "{good} of {total} pixels ({:.3}%) within tolerance; the others may legitimately differ: a \
             transmittance crossing 1e-4 or an alpha crossing 1/255 on one side only",
            100.0 * fraction
        )
    };
    (fraction >= RENDER_PIXEL_FRACTION, note)
}

/// Compares the port's value `actual` of output `name` with `reference`.
pub(super) fn compare(name: &str, actual: &Actual, reference: &HostTensor) -> ParityRow {
    if actual.tensor.shape != reference.shape {
        return ParityRow::not_compared(name, &reference.shape, Status::ShapeMismatch(actual.tensor.shape.clone()));
    }
    let found = differences(actual, reference);
    let tolerance = NETWORK.allowed_f32(found.max_reference);
    let (within, note) = match actual.pixel_channels {
        None => (found.max_abs <= tolerance, actual.note.map(str::to_string)),
        Some(channels) => {
            let (within, note) = pixels_within(actual, reference, channels, tolerance);
            (within, Some(note))
        }
    };
    let status = match (found.finite, within) {
        (false, _) => Status::NotFinite,
        (true, true) => Status::Pass,
        (true, false) => Status::OutOfTolerance,
    };
    ParityRow {
        name: name.to_string(),
        shape: reference.shape.clone(),
        max_abs: Some(f64::from(found.max_abs)),
        max_rel: Some(f64::from(found.max_abs / found.max_reference.max(f32::MIN_POSITIVE))),
        tolerance: Some(f64::from(tolerance)),
        status,
        note: if found.finite { note } else { None },
    }
}
