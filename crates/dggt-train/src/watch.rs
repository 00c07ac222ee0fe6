//! Watching a run while it trains: what the loop hands an observer (a live viewer) after each step and each
//! validation pass, as plain host data, so that the observer needs neither the network nor a device.
//!
//! The loop calls a [`RunWatcher`] on the writing rank only, after the step's record is in `metrics.jsonl` and
//! after a validation pass is recorded. A watcher only reads: the weights, the sampling and the schedule never
//! depend on it, so a watched run trains exactly as an unwatched one. A validation pass pictures its first scene
//! ([`crate::snapshot`]) only when the watcher asks for it, since that copies the window's images and Gaussians
//! to the host.

use crate::records::LoggedStep;
use crate::snapshot::SnapshotOptions;
use crate::validate::Validation;

/// An observer of a run (see the module's doc). Its methods cannot fail: a watcher deals with its own
/// troubles (a viewer that went away, say) without stopping the run.
pub trait RunWatcher {
    /// A trained (or skipped) step's record, as `metrics.jsonl` holds it.
    fn step(&mut self, step: &LoggedStep<'_>);
    /// Whether the validation pass at `step` should picture its first scene, and how.
    fn snapshot_wanted(&self, step: u64) -> Option<SnapshotOptions>;
    /// A validation pass of the scored weights at `step` (its snapshot inside, when one was wanted).
    fn validation(&mut self, step: u64, validation: &Validation);
}

/// A watcher that watches nothing: [`Trainer::run`](crate::Trainer::run)'s.
pub(crate) struct Unwatched;

impl RunWatcher for Unwatched {
    fn step(&mut self, _: &LoggedStep<'_>) {}

    fn snapshot_wanted(&self, _: u64) -> Option<SnapshotOptions> {
        None
    }

    fn validation(&mut self, _: u64, _: &Validation) {}
}
