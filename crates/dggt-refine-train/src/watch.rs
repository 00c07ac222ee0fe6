//! Watching the refiner's training while it runs: what the loop hands an observer (a live viewer) after each
//! step and each validation pass, as host images. A watcher only reads: the weights, the pairs drawn and the
//! latents never depend on it, so a watched run trains exactly as an unwatched one.

use crate::pairs::Image;
use crate::records::{StepRecord, Validation};

/// An observer of a refiner run. Its methods cannot fail: a watcher deals with its own troubles.
pub trait RefineWatcher {
    fn step(&mut self, record: &StepRecord);
    /// How many held-out pairs the coming validation pass should picture (0: none).
    fn pictures_wanted(&self) -> usize;
    /// A validation pass: its scores and the first held-out pairs, as asked.
    fn validation(&mut self, validation: &Validation, pictures: &[RefinedPicture]);
}

/// A watcher that watches nothing.
pub(crate) struct Unwatched;

impl RefineWatcher for Unwatched {
    fn step(&mut self, _: &StepRecord) {}

    fn pictures_wanted(&self) -> usize {
        0
    }

    fn validation(&mut self, _: &Validation, _: &[RefinedPicture]) {}
}

/// One held-out pair at a validation pass: `[H, W, 3]` values in `[0, 1]`, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct RefinedPicture {
    /// Position among the held-out pairs.
    pub index: usize,
    /// The render with artifacts, before refining.
    pub render: Image,
    /// The refiner's output (from the posterior mean).
    pub refined: Image,
    /// The ground truth.
    pub target: Image,
}
