//! Skipping loss spikes (`[optim.skip_loss_spikes]`).
//!
//! Now and then a draw of samples gives a loss many times the recent ones: a view where the predicted depth
//! put Gaussians over the whole sky, say. Its gradient, clipped or not, points wherever that one sample wants,
//! and Adam's per-parameter normalisation turns it into a full-sized step on parameters that rarely move; late in
//! a small run one such step can cost a decibel that the rest of the schedule does not win back. A step whose
//! loss exceeds `factor` times the median of the last `window` steps' finite losses therefore makes no update
//! (the weights and moments stay as they were), is counted (`spike_skipped_steps`) and warned about. Every finite
//! loss joins the window, skipped ones included, so a lasting rise of the loss (a harder stage of a curriculum)
//! moves the median within half a window instead of skipping every step. The window is part of the run state, so
//! a resumed run judges its steps as the uninterrupted one would.

use std::fmt;

use crate::optim_config::SpikeSection;

/// A loss judged a spike, with the median it was judged against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spike {
    pub loss: f64,
    pub median: f64,
}

impl fmt::Display for Spike {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "loss spike ({:.4}, {:.1} times the recent median {:.4})",
            self.loss,
            self.loss / self.median,
            self.median
        )
    }
}

/// Whether `loss` is a spike against `recent` (the last steps' losses), as `section` defines one; never
/// before the window is full.
pub fn judge(recent: &[f64], loss: f64, section: &SpikeSection) -> Option<Spike> {
    if recent.len() < section.window {
        return None;
    }
    let median = median(recent);
    (loss > section.factor * median).then_some(Spike { loss, median })
}

/// Adds a finite `loss` to `recent`, keeping the newest `window`.
pub fn remember(recent: &mut Vec<f64>, loss: f64, window: usize) {
    if !loss.is_finite() {
        return;
    }
    recent.push(loss);
    let excess = recent.len().saturating_sub(window);
    recent.drain(..excess);
}

fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let middle = sorted.len() / 2;
    match sorted.len() % 2 {
        0 => (sorted[middle - 1] + sorted[middle]) / 2.0,
        _ => sorted[middle],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loss_above_factor_times_the_window_median_is_a_spike_once_the_window_is_full() {
        let section = SpikeSection { factor: 3.0, window: 4 };
        let mut recent = Vec::new();
        for loss in [0.01, 0.03, 0.02] {
            remember(&mut recent, loss, section.window);
        }
        assert_eq!(judge(&recent, 1.0, &section), None, "no judgement before the window is full");
        remember(&mut recent, 0.04, section.window);
        // Median of 0.01, 0.02, 0.03, 0.04: 0.025; the bound is 0.075.
        assert_eq!(judge(&recent, 0.07, &section), None);
        let spike = judge(&recent, 0.08, &section).expect("a spike");
        assert!((spike.median - 0.025).abs() < 1e-12, "{spike}");
        assert!(spike.to_string().starts_with("loss spike (0.0800, 3.2 times the recent median 0.0250)"), "{spike}");

        // The window keeps the newest losses, skipped ones included, and never a non-finite one.
        remember(&mut recent, 0.08, section.window);
        remember(&mut recent, f64::NAN, section.window);
        assert_eq!(recent, vec![0.03, 0.02, 0.04, 0.08]);
    }
}
