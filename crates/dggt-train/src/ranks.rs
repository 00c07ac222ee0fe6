//! A run over several processes (the ranks of an MPI job): which samples each rank draws, what the ranks
//! decide together, and the checks that they stay one run.
//!
//! P ranks of D devices at `optim.accumulation` A are one run of P·D·A samples a step, the run that one process
//! at accumulation P·A (on D devices) would make: step `s` draws the samples `s·P·D·A ..` of the shared seeded
//! sequence, and rank `r` takes the contiguous block `s·P·D·A + r·D·A .. + D·A` of them (its devices split the
//! block as devices do in one process). The loss of every sample is scaled by one over the step's P·D·A
//! samples, so the sum over ranks is the step's mean gradient; with one device per rank and A = 1 it is the
//! sum one process takes, term for term.
//!
//! Rank 0 alone decides what depends on the output folder and the clock (whether the folder may be used,
//! which checkpoint to resume, whether the time limit has come) and tells the others; rank 0 alone writes.

use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::Tensor;
use dggt_collective::ProcessGroup;
use dggt_model::Dggt;
use dggt_model::host::host_f32;
use dggt_objective::LossTerm;

use crate::error::TrainError;
use crate::records::StepMeasures;

/// The sample positions of rank `rank` of `ranks` from step `first_step` on, `local` samples a step each.
pub fn sample_positions(first_step: u64, local: u64, rank: usize, ranks: usize) -> impl Iterator<Item = u64> + Send {
    let (rank, global) = (rank as u64, local * ranks as u64);
    (first_step..).flat_map(move |step| (0..local).map(move |j| step * global + rank * local + j))
}

/// What rank 0 found when it checked the output folder, as it is broadcast.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FolderOutcome {
    /// A fresh start, or a resume without a checkpoint.
    NoCheckpoint,
    /// Resume the checkpoint of this step.
    Resume(u64),
    /// Rank 0 refused the folder (its error says why).
    Refused,
}

const NO_CHECKPOINT: u64 = u64::MAX;
const REFUSED: u64 = u64::MAX - 1;

impl FolderOutcome {
    fn encode(self) -> u64 {
        match self {
            Self::NoCheckpoint => NO_CHECKPOINT,
            Self::Resume(step) => step,
            Self::Refused => REFUSED,
        }
    }

    fn decode(value: u64) -> Self {
        match value {
            NO_CHECKPOINT => Self::NoCheckpoint,
            REFUSED => Self::Refused,
            step => Self::Resume(step),
        }
    }
}

/// The checkpoint every rank starts from: rank 0 runs `decide` (checks the output folder, finds the checkpoint
/// and prepares the folder) while the others wait, then tells them its outcome, so that no rank checks a
/// folder another is already writing into. The others resume the checkpoint folder of the step rank 0 names
/// under `checkpoints`.
pub fn agree_on_start<T>(
    group: &ProcessGroup,
    checkpoints: &Path,
    decide: impl FnOnce() -> Result<(Option<PathBuf>, T), TrainError>,
    follow: impl FnOnce() -> Result<T, TrainError>,
) -> Result<(Option<PathBuf>, T), TrainError> {
    if group.size() == 1 {
        return decide();
    }
    if group.is_writer() {
        let decided = decide();
        let outcome = match &decided {
            Err(_) => FolderOutcome::Refused,
            Ok((None, _)) => FolderOutcome::NoCheckpoint,
            Ok((Some(dir), _)) => FolderOutcome::Resume(checkpoint_step(dir)?),
        };
        group.broadcast_u64(outcome.encode());
        return decided;
    }
    match FolderOutcome::decode(group.broadcast_u64(0)) {
        FolderOutcome::Refused => Err(TrainError::RankFailed { what: "preparing the output folder" }),
        FolderOutcome::NoCheckpoint => Ok((None, follow()?)),
        FolderOutcome::Resume(step) => Ok((Some(checkpoints.join(format!("step-{step:08}"))), follow()?)),
    }
}

/// The step of a checkpoint folder, from its run state.
fn checkpoint_step(dir: &Path) -> Result<u64, TrainError> {
    Ok(dggt_run::checkpoint::read_state(dir)?.step)
}

/// Rank 0's `decision` on every rank (a clock that says the run is over).
pub fn rank_zero_decides(group: &ProcessGroup, decision: bool) -> bool {
    if group.size() == 1 { decision } else { group.broadcast_u64(u64::from(decision)) == 1 }
}

/// Sums a step's measures over the ranks (each rank's are already scaled by one over the step's samples, so
/// the sums are the step's means); `None` on every rank when any rank's loss was not finite. Timings stay
/// this rank's.
pub fn sum_measures(group: &ProcessGroup, measures: Option<StepMeasures>) -> Result<Option<StepMeasures>, TrainError> {
    if group.size() == 1 {
        return Ok(measures);
    }
    let local = measures.clone().unwrap_or_default();
    let mut values = vec![if measures.is_some() { 0.0 } else { 1.0 }, local.loss, local.target_psnr];
    values.push(local.gaussians_kept as f64);
    for term in LossTerm::ALL {
        let value = local.terms.get(term.name());
        values.extend([value.copied().unwrap_or(0.0), if value.is_some() { 1.0 } else { 0.0 }]);
    }
    group.all_reduce_sum_f64(&mut values)?;
    let Some(mut summed) = measures else { return Ok(None) };
    if values[0] > 0.0 {
        return Ok(None);
    }
    summed.loss = values[1];
    summed.target_psnr = values[2];
    summed.gaussians_kept = values[3] as usize;
    summed.terms.clear();
    for (term, pair) in LossTerm::ALL.into_iter().zip(values[4..].chunks(2)) {
        if pair[1] > 0.0 {
            summed.terms.insert(term.name().to_string(), pair[0]);
        }
    }
    Ok(Some(summed))
}

/// The number of `count` summed over the ranks (samples that failed to load this step).
pub fn sum_count(group: &ProcessGroup, count: u64) -> Result<u64, TrainError> {
    let mut value = [count as f64];
    group.all_reduce_sum_f64(&mut value)?;
    Ok(value[0] as u64)
}

/// Checks that every rank holds the same weights (bit for bit); returns their checksum. Each rank reads its
/// weights back tensor by tensor; rank 0's checksum is compared everywhere and the mismatches summed, so a
/// rank out of step fails the run on every rank.
pub fn check_in_step(group: &ProcessGroup, model: &Dggt) -> Result<u64, TrainError> {
    let mut checksum = WeightChecksum::default();
    model.visit(&mut checksum);
    if let Some(error) = checksum.failure {
        return Err(error.into());
    }
    let ours = checksum.hash;
    let theirs = group.broadcast_u64(ours);
    let mut differing = [f64::from(u8::from(ours != theirs))];
    group.all_reduce_sum_f64(&mut differing)?;
    if differing[0] > 0.0 {
        return Err(TrainError::RanksOutOfStep { ranks: differing[0] as usize, checksum: theirs });
    }
    Ok(ours)
}

/// FNV-1a over the bits of every weight, in the module's parameter order.
struct WeightChecksum {
    hash: u64,
    failure: Option<dggt_model::host::ReadBackError>,
}

impl Default for WeightChecksum {
    fn default() -> Self {
        Self { hash: 0xcbf2_9ce4_8422_2325, failure: None }
    }
}

impl ModuleVisitor for WeightChecksum {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        match host_f32(param.val(), "a weight") {
            Ok(values) => {
                for byte in values.iter().flat_map(|v| v.to_bits().to_le_bytes()) {
                    self.hash = (self.hash ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3);
                }
            }
            Err(error) => {
                self.failure.get_or_insert(error);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_take_contiguous_blocks_that_together_are_the_single_process_sequence() {
        let (local, ranks) = (3, 4);
        let per_rank: Vec<Vec<u64>> =
            (0..ranks).map(|r| sample_positions(2, local, r, ranks).take(3 * local as usize).collect()).collect();
        let mut merged: Vec<u64> = Vec::new();
        for step in 0..3 {
            for rank in &per_rank {
                merged.extend(&rank[step * local as usize..(step + 1) * local as usize]);
            }
        }
        let single: Vec<u64> = sample_positions(2, local * ranks as u64, 0, 1).take(merged.len()).collect();
        assert_eq!(merged, single);
        assert_eq!(per_rank[1][..3], [27, 28, 29], "step 2, rank 1 of 4 at 3 samples each");
    }

    #[test]
    fn folder_outcomes_survive_the_broadcast() {
        for outcome in [FolderOutcome::NoCheckpoint, FolderOutcome::Refused, FolderOutcome::Resume(0)] {
            assert_eq!(FolderOutcome::decode(outcome.encode()), outcome);
        }
    }
}
