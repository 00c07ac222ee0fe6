//! The training loop.
//!
//! Each optimiser step draws `accumulation` samples for every device (sample `k = step · samples_per_step + j`,
//! a pure function of the seed; a run of several processes draws each rank's share, [`ranks`]); every device
//! computes its samples' losses and gradients on its own replica of the network (one thread each), the
//! gradients are all-reduced ([`replicas`](crate::replicas), then across ranks,
//! [`rank_gradients`](crate::rank_gradients)), and every
//! replica clips the global norm and steps AdamW per parameter group at the scheduled rate. A sample with
//! a non-finite loss or network output (a depth that overflowed, say), or a step with a non-finite gradient
//! norm, is skipped with a warning and leaves the weights untouched; an update that makes a weight or moment
//! non-finite is rolled back; a checkpoint falling due meanwhile waits for a step that trains, and too many
//! such steps in a row stop the run ([`divergence`]). With `optim.skip_loss_spikes`, a step whose loss jumps far
//! above the recent ones makes no update either ([`spikes`]); with `optim.average`, an average of the weights is
//! kept beside them ([`average`]). Metrics go to
//! `metrics.jsonl` ([`records`](crate::records)), checkpoints to `checkpoints/` (see [`checkpoint`]); an error
//! of a validation pass names the step it validated. Of several ranks, rank 0 alone writes them, validates and
//! draws the progress bar.
//!
//! One module per phase, each using only those before it: `datasets` (the datasets indexed, the validation
//! scenes picked), `setup` (the trainer built fresh or resumed, and what it exposes), `step` (one optimiser
//! step), `validation` (the weights scored and a validation pass recorded), `checkpoints` (a checkpoint of the
//! run written) and `run` (the loop over the steps, and the summary of how it ended).
//!
//! [`checkpoint`]: crate::checkpoint
//! [`average`]: dggt_run::average
//! [`ranks`]: crate::ranks
//! [`divergence`]: dggt_run::divergence
//! [`spikes`]: dggt_run::spikes

mod checkpoints;
mod datasets;
mod run;
mod setup;
mod step;
mod validation;

pub use datasets::SCENE_INDEX;
pub use run::{RunOptions, RunSummary};
pub use setup::Trainer;
