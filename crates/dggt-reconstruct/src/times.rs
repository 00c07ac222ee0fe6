//! The render times a reconstruction is asked for, checked before any work: each requested time must lie
//! within the input frames' time window, and `--every` within its range, so that a mistyped value is refused
//! with the range it should take. How much those times would write is [`crate::volume`]'s check.

use crate::error::ReconstructError;

/// The most render times `--every` puts in each interval between input frames (a render every millisecond
/// between frames of a 10 Hz log).
pub const MAX_EVERY: usize = 100;

/// Checks requested times (seconds since the first chosen frame) against the input frames' times `inputs`
/// (ascending): each must be finite and lie within them.
pub fn check_times(times: &[f64], inputs: &[f64]) -> Result<(), ReconstructError> {
    let (Some(&first), Some(&last)) = (inputs.first(), inputs.last()) else { return Ok(()) };
    if times.is_empty() {
        return Err(ReconstructError::option("--times", "no times given"));
    }
    let outside = times.iter().find(|t| !(t.is_finite() && (first..=last).contains(*t)));
    match outside {
        None => Ok(()),
        Some(time) => Err(ReconstructError::option(
            "--times",
            format!(
                "{time} s lies outside the input frames' time window: give seconds in {first:.3}..={last:.3} (the \
                 chosen frames' times)"
            ),
        )),
    }
}

/// Checks `--every K` against its range, `1..=MAX_EVERY`.
pub fn check_every(every: usize) -> Result<(), ReconstructError> {
    if (1..=MAX_EVERY).contains(&every) {
        return Ok(());
    }
    Err(ReconstructError::option(
        "--every",
        format!("{every} is outside 1..={MAX_EVERY} (render times per interval between input frames)"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_past_the_inputs_and_every_past_its_range_are_refused() {
        let inputs = [0.0, 0.1, 0.2];
        check_times(&[0.0, 0.15, 0.2], &inputs).unwrap();
        let error = check_times(&[0.1, 1e9], &inputs).unwrap_err().to_string();
        assert!(
            error.contains("--times") && error.contains("1000000000") && error.contains("0.000..=0.200"),
            "{error}"
        );
        assert!(check_times(&[f64::NAN], &inputs).is_err());
        check_every(MAX_EVERY).unwrap();
        let error = check_every(100_000).unwrap_err().to_string();
        assert!(error.contains("--every") && error.contains("100000") && error.contains("1..=100"), "{error}");
    }
}
