//! Divergence: steps that change nothing because the numbers left the finite range, and when to give up.
//!
//! A step fails when its loss or gradient norm is not finite (it is skipped) or when its update makes a weight
//! or an AdamW moment non-finite (it is rolled back, see [`Optimizer::step`](crate::optimizer::Optimizer::step));
//! either way the weights keep their last finite values. A failed step now and then is survivable (one bad
//! sample); several in a row mean the run has diverged, usually a learning rate too high for the network, and
//! nothing will change by itself. Past `optim.max_failed_steps_in_a_row` such steps the run therefore stops
//! with [`RunError::Diverged`], which says what to change. The count is part of the run state, so a resumed
//! run continues it.
//!
//! Weights that are finite can still be what makes every step fail (their outputs overflow), so a checkpoint
//! of them could replace, and prune, the last one from before: a periodic checkpoint that falls due while steps
//! are failing waits for the next step that trains ([`CheckpointGate`]).

use std::ops::RangeInclusive;

use crate::checkpoint::RunState;
use crate::error::RunError;
use crate::finite::NonFinite;
use crate::optimizer::StepOutcome;
use crate::spikes::Spike;

/// The values `optim.max_failed_steps_in_a_row` takes.
pub const MAX_FAILED_STEPS_IN_A_ROW_RANGE: RangeInclusive<u64> = 1..=10_000;

/// Why a step made no update.
#[derive(Debug, Clone, PartialEq)]
pub enum StepFailure {
    /// A sample's loss or network output was not finite: skipped.
    NonFiniteLoss,
    /// The gradient norm was not finite: skipped.
    NonFiniteGradient,
    /// The update made the named tensor non-finite: rolled back.
    RolledBack(NonFinite),
    /// The loss jumped above `optim.skip_loss_spikes.factor` times the recent median: skipped. Not a failure of
    /// the weights: it neither counts towards divergence nor holds back a checkpoint.
    LossSpike(Spike),
}

impl StepFailure {
    /// The failure an optimiser step reports, if it failed.
    pub fn of(outcome: &StepOutcome) -> Option<Self> {
        match outcome {
            StepOutcome::Applied(_) => None,
            StepOutcome::NonFiniteGradient => Some(Self::NonFiniteGradient),
            StepOutcome::RolledBack { non_finite, .. } => Some(Self::RolledBack(non_finite.clone())),
        }
    }

    /// What happened, for the log and the metrics record.
    pub fn describe(&self) -> String {
        match self {
            Self::NonFiniteLoss => "non-finite loss: step skipped, weights untouched".into(),
            Self::NonFiniteGradient => "non-finite gradient: step skipped, weights untouched".into(),
            Self::RolledBack(tensor) => {
                format!("the update made the {tensor} non-finite: step rolled back, weights and moments restored")
            }
            Self::LossSpike(spike) => format!("{spike}: step skipped, weights untouched"),
        }
    }
}

/// What the divergence check needs of the configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DivergenceLimit {
    /// Failed steps in a row that stop the run (`optim.max_failed_steps_in_a_row`).
    pub max_failed_in_a_row: u64,
    /// The peak learning rate, named in the error.
    pub lr: f64,
}

/// Counts step `step`'s outcome in `state`: a failure is warned about and added to its counter and to the
/// failures in a row; a step that trained ends the row.
pub fn count_step(state: &mut RunState, step: u64, failure: Option<&StepFailure>) {
    let Some(failure) = failure else {
        state.failed_in_a_row = 0;
        return;
    };
    match failure {
        StepFailure::RolledBack(_) => state.rolled_back_steps += 1,
        StepFailure::NonFiniteLoss | StepFailure::NonFiniteGradient => state.skipped_steps += 1,
        StepFailure::LossSpike(_) => {
            state.spike_skipped_steps += 1;
            tracing::warn!(step, "{}", failure.describe());
            return;
        }
    }
    state.failed_in_a_row += 1;
    tracing::warn!(step, in_a_row = state.failed_in_a_row, "{}", failure.describe());
}

/// [`RunError::Diverged`] once `limit` steps in a row have failed, the last of them with `last_failure`;
/// called after [`count_step`] (`state.step` is the next step).
pub fn check(state: &RunState, last_failure: Option<&StepFailure>, limit: DivergenceLimit) -> Result<(), RunError> {
    if state.failed_in_a_row < limit.max_failed_in_a_row {
        return Ok(());
    }
    Err(RunError::Diverged {
        first_step: state.step.saturating_sub(state.failed_in_a_row),
        last_step: state.step.saturating_sub(1),
        last_failure: last_failure.map_or_else(|| "unknown".into(), StepFailure::describe),
        lr: limit.lr,
        limit: limit.max_failed_in_a_row,
    })
}

/// Whether a checkpoint falls due after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CheckpointDue {
    No,
    /// Every `run.checkpoint_every` steps.
    Periodic,
    /// The run's last step: written whatever the last steps did.
    EndOfRun,
}

/// Holds back periodic checkpoints while steps are failing.
#[derive(Debug, Default)]
pub struct CheckpointGate {
    postponed: bool,
}

impl CheckpointGate {
    /// Whether to write a checkpoint now, after the step that left `state`, when `due` says one falls due: a
    /// periodic one (or one postponed before) only when that step trained, the one at the end of a run always.
    pub fn write_now(&mut self, state: &RunState, due: CheckpointDue) -> bool {
        let wanted = self.postponed || due != CheckpointDue::No;
        let now = wanted && (state.failed_in_a_row == 0 || due == CheckpointDue::EndOfRun);
        if wanted && !now && !self.postponed {
            tracing::warn!(step = state.step, "checkpoint postponed until a step trains");
        }
        self.postponed = wanted && !now;
        now
    }
}

/// Refuses a `max_failed_steps_in_a_row` outside [`MAX_FAILED_STEPS_IN_A_ROW_RANGE`].
pub fn validate_limit(setting: &'static str, value: u64) -> Result<(), RunError> {
    if MAX_FAILED_STEPS_IN_A_ROW_RANGE.contains(&value) {
        return Ok(());
    }
    let (low, high) = (MAX_FAILED_STEPS_IN_A_ROW_RANGE.start(), MAX_FAILED_STEPS_IN_A_ROW_RANGE.end());
    Err(RunError::Setting { setting, detail: format!("must lie in [{low}, {high}], got {value}") })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::finite::Holder;

    #[test]
    fn failures_in_a_row_stop_the_run_and_a_step_that_trains_ends_the_row() {
        let mut state = RunState::starting(0, 1);
        let limit = DivergenceLimit { max_failed_in_a_row: 3, lr: 0.5 };
        let rolled_back = StepFailure::RolledBack(NonFinite { parameter: "gs_head.w".into(), holder: Holder::Weight });
        let outcomes = [Some(StepFailure::NonFiniteLoss), Some(rolled_back.clone()), None];
        let outcomes = outcomes.into_iter().chain([Some(StepFailure::NonFiniteGradient), Some(rolled_back.clone())]);
        for (step, failure) in outcomes.enumerate() {
            count_step(&mut state, step as u64, failure.as_ref());
            state.step += 1;
            check(&state, failure.as_ref(), limit).unwrap();
        }
        assert_eq!((state.failed_in_a_row, state.skipped_steps, state.rolled_back_steps), (2, 2, 2));
        count_step(&mut state, 5, Some(&rolled_back));
        state.step += 1;
        let error = check(&state, Some(&rolled_back), limit).unwrap_err().to_string();
        assert!(error.starts_with("training diverged: the 3 steps 3..=5 in a row made no update"), "{error}");
        assert!(error.contains("weight `gs_head.w` non-finite") && error.contains("optim.lr is 0.5"), "{error}");
    }

    #[test]
    fn a_checkpoint_due_while_steps_fail_waits_for_a_step_that_trains() {
        let mut gate = CheckpointGate::default();
        let failing = RunState { failed_in_a_row: 2, ..RunState::starting(0, 1) };
        let training = RunState::starting(0, 1);
        assert!(gate.write_now(&training, CheckpointDue::Periodic));
        assert!(!gate.write_now(&training, CheckpointDue::No));
        assert!(!gate.write_now(&failing, CheckpointDue::Periodic), "held back");
        assert!(!gate.write_now(&failing, CheckpointDue::No), "still held back");
        assert!(gate.write_now(&training, CheckpointDue::No), "written after the next step that trains");
        assert!(!gate.write_now(&training, CheckpointDue::No), "once");
        assert!(gate.write_now(&failing, CheckpointDue::EndOfRun), "the end of a run is always written");
    }
}
