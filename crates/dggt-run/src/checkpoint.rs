//! Checkpoint folders: everything a run needs to continue exactly as if it had not stopped.
//!
//! The folder's format (its file names, its checksums, the `latest` pointer, a module's weights written and
//! read) is [`dggt_checkpoint`]'s, which inference shares; this module adds the optimiser and run state and
//! writes all of it, for any trained module. A trainer adds its own files (the DGGT trainer: the network's
//! configuration, preprocessing and configured sections).
//!
//! A checkpoint is a folder `checkpoints/step-NNNNNNNN/` holding the module (`model.bpk`, burnpack, parameter
//! ids included so the optimiser state stays attached), the AdamW state (`optimizer.bpk`), the trainer's own
//! files and the run state (`state.json`: the next step, seed and counters). The learning-rate schedule is a
//! function of the step and the samplers draw from `(seed, step)`, so no random-generator state needs saving.
//! The weights and moments are written tensor by tensor (peak host memory is one tensor, not the 16 GB of a
//! full-size model and its AdamW state). Every file is written through a temporary file and a rename;
//! `checksums.json` records every file's size and CRC-32C ([`dggt_checkpoint::checksums`]), `state.json` then
//! marks the folder complete and the `checkpoints/latest` pointer is replaced last: a run killed at any moment,
//! in the middle of a checkpoint included, resumes from the last complete one, and one whose newest checkpoint
//! was damaged afterwards from the newest intact one. No checkpoint is written with a non-finite weight or
//! moment.
//!
//! A run that averages its weights ([`crate::average`]) stores the average as `model.bpk`, the weights
//! inference and fine-tuning load, and the trained weights the optimiser steps as `trained.bpk`, which a
//! resume continues from ([`load_trained`]).

use std::fs;
use std::path::{Path, PathBuf};

use burn::module::Module;
use dggt_checkpoint::checksums;
pub use dggt_checkpoint::{
    LATEST, MANIFEST_FILE, MODEL_FILE, Purpose, STATE_FILE, latest, load_model, load_module_file, save_model, verified,
};
use dggt_data::io::write_atomically;
use serde::{Deserialize, Serialize};

use crate::error::RunError;
use crate::failpoint;
use crate::finite::first_non_finite;
use crate::optimizer::Optimizer;

/// The counters of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunState {
    /// The next optimiser step to run.
    pub step: u64,
    pub seed: u64,
    /// Steps skipped for a non-finite loss or gradient.
    pub skipped_steps: u64,
    /// Steps whose update made a weight or moment non-finite and was undone.
    #[serde(default)]
    pub rolled_back_steps: u64,
    /// Steps skipped or rolled back since the last step that trained (the divergence check counts them).
    #[serde(default)]
    pub failed_in_a_row: u64,
    /// Training seconds before this checkpoint (summed over resumed segments).
    pub elapsed_s: f64,
    /// Samples that failed to load and were replaced.
    #[serde(default)]
    pub bad_samples: u64,
    /// Samples drawn per step (`optim.accumulation` x devices) when the checkpoint was written; 0 when unknown.
    #[serde(default)]
    pub samples_per_step: u64,
    /// Steps whose update was skipped as a loss spike ([`crate::spikes`]).
    #[serde(default)]
    pub spike_skipped_steps: u64,
    /// The last steps' finite losses, oldest first, that the next spike is judged against ([`crate::spikes`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recent_losses: Vec<f64>,
}

impl RunState {
    /// The counters of a run that has not taken a step yet.
    pub fn starting(seed: u64, samples_per_step: u64) -> Self {
        Self {
            step: 0,
            seed,
            skipped_steps: 0,
            rolled_back_steps: 0,
            failed_in_a_row: 0,
            elapsed_s: 0.0,
            bad_samples: 0,
            samples_per_step,
            spike_skipped_steps: 0,
            recent_losses: Vec::new(),
        }
    }
}

/// The optimiser's state in a checkpoint folder.
const OPTIMIZER_FILE: &str = "optimizer.bpk";
/// The trained weights in a checkpoint folder whose `model.bpk` holds their average.
pub const TRAINED_FILE: &str = "trained.bpk";

// Takes any error by value, like `impl Into<String>`, so `map_err(|e| ..(path, e))` reads plainly.
#[allow(clippy::needless_pass_by_value)]
fn checkpoint_error(path: &Path, detail: impl ToString) -> RunError {
    RunError::Checkpoint { path: path.to_path_buf(), detail: detail.to_string() }
}

/// The weights a checkpoint holds.
#[derive(Debug)]
pub enum Weights<'a, M> {
    /// The trained weights alone (`model.bpk`).
    Trained(&'a M),
    /// The average of the weights (`model.bpk`) and the trained ones (`trained.bpk`).
    Averaged { trained: &'a M, average: &'a M },
}

// By hand: references are copied whatever `M` is (the derive would ask `M: Copy`).
impl<M> Clone for Weights<'_, M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M> Copy for Weights<'_, M> {}

impl<M: Module> Weights<'_, M> {
    /// Each module with the file it is written to.
    fn files(&self) -> Vec<(&'static str, &M)> {
        match *self {
            Self::Trained(trained) => vec![(MODEL_FILE, trained)],
            Self::Averaged { trained, average } => vec![(MODEL_FILE, average), (TRAINED_FILE, trained)],
        }
    }

    fn first_non_finite(&self, optimizer: &Optimizer) -> Option<crate::finite::NonFinite> {
        match *self {
            Self::Trained(trained) => first_non_finite(trained, Some(optimizer)),
            Self::Averaged { trained, average } => {
                first_non_finite(trained, Some(optimizer)).or_else(|| first_non_finite(average, None))
            }
        }
    }
}

/// Writes a checkpoint of any trained module under `root` (`run/checkpoints`): its weights, the optimiser,
/// `extra` files (name, bytes) and the run state, written last, in `root/step-NNNNNNNN/`; then `latest` and
/// pruning to the newest `keep`. Nothing is written when a weight or moment is not finite.
pub fn save_folder<M: Module>(
    root: &Path,
    weights: Weights<'_, M>,
    optimizer: &Optimizer,
    state: &RunState,
    keep: usize,
    extra: &[(&str, &[u8])],
) -> Result<PathBuf, RunError> {
    let name = format!("step-{:08}", state.step);
    let dir = root.join(&name);
    if let Some(non_finite) = weights.first_non_finite(optimizer) {
        return Err(RunError::NonFiniteCheckpoint { dir, non_finite });
    }
    fs::create_dir_all(&dir).map_err(|e| checkpoint_error(&dir, e))?;
    let write = |file: &str, bytes: &[u8]| -> Result<(), RunError> {
        write_atomically(&dir.join(file), bytes).map_err(|e| checkpoint_error(&dir.join(file), e))
    };
    // The run state goes last: a folder without it is incomplete and never resumed from.
    // So is the trained weights' file of an earlier write of this folder: its presence says `model.bpk` is an
    // average.
    for stale in [STATE_FILE, TRAINED_FILE] {
        let _ = fs::remove_file(dir.join(stale));
    }
    let modules = weights.files();
    for (file, module) in &modules {
        save_model(&dir.join(file), *module)?;
    }
    failpoint::reached(failpoint::INSIDE_CHECKPOINT);
    optimizer.save(&dir.join(OPTIMIZER_FILE))?;
    for (file, bytes) in extra {
        write(file, bytes)?;
    }
    let state_bytes = serde_json::to_string_pretty(state).expect("states serialise").into_bytes();
    let written: Vec<&str> = modules
        .iter()
        .map(|(name, _)| *name)
        .chain([OPTIMIZER_FILE])
        .chain(extra.iter().map(|(name, _)| *name))
        .collect();
    checksums::write_manifest(&dir, &written, &[(STATE_FILE, &state_bytes)])?;
    write(STATE_FILE, &state_bytes)?;
    write_atomically(&root.join(LATEST), name.as_bytes()).map_err(|e| checkpoint_error(&root.join(LATEST), e))?;
    prune(root, keep.max(1))?;
    Ok(dir)
}

/// Removes all but the newest `keep` `step-*` folders under `root`.
pub fn prune(root: &Path, keep: usize) -> Result<(), RunError> {
    let mut steps: Vec<PathBuf> = fs::read_dir(root)
        .map_err(|e| checkpoint_error(root, e))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|p| p.is_dir() && p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("step-")))
        .collect();
    steps.sort();
    let excess = steps.len().saturating_sub(keep);
    for old in &steps[..excess] {
        fs::remove_dir_all(old).map_err(|e| checkpoint_error(old, e))?;
    }
    Ok(())
}

/// The trained weights of the checkpoint folder `dir` loaded into `blank`, with their average when the
/// checkpoint holds one (without autodiff).
pub fn load_trained<M: Module>(dir: &Path, blank: M) -> Result<(M, Option<M>), RunError> {
    let trained_file = dir.join(TRAINED_FILE);
    if !trained_file.is_file() {
        return Ok((load_model(dir, blank)?, None));
    }
    let trained = load_module_file(&trained_file, blank.clone())?;
    let average = load_model(dir, blank)?.valid();
    Ok((trained, Some(average)))
}

/// The run state of the checkpoint folder `dir` (`state.json`).
pub fn read_state(dir: &Path) -> Result<RunState, RunError> {
    let path = dir.join(STATE_FILE);
    let bytes = fs::read(&path).map_err(|e| checkpoint_error(&path, e))?;
    serde_json::from_slice(&bytes).map_err(|e| checkpoint_error(&path, e))
}

/// The AdamW state's file in a checkpoint folder (see [`Optimizer::load`]).
pub fn optimizer_file(dir: &Path) -> PathBuf {
    dir.join(OPTIMIZER_FILE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::average::tests::{Pair, Values};
    use crate::optim_config::OptimSection;

    fn trained_values(dir: &Path, like: &Pair) -> (Values, Option<Values>) {
        let (trained, average) = load_trained(dir, Pair::new([0.0, 0.0], 0.0, Some(like))).unwrap();
        (trained.values(), average.map(|a| a.values()))
    }

    #[test]
    fn an_averaging_run_gives_inference_the_average_and_a_resume_the_trained_weights() {
        let root = tempfile::tempdir().unwrap();
        let optimizer = Optimizer::ungrouped(&OptimSection::default());
        let trained = Pair::new([1.0, 2.0], 5.0, None);
        let average = Pair::new([3.0, 4.0], 5.0, Some(&trained));
        let state = RunState::starting(0, 1);
        let weights = Weights::Averaged { trained: &trained, average: &average };
        let dir = save_folder(root.path(), weights, &optimizer, &state, 2, &[]).unwrap();

        let inference = load_model(&dir, Pair::new([0.0, 0.0], 0.0, Some(&trained))).unwrap();
        assert_eq!(inference.values(), (vec![3.0, 4.0], vec![5.0]), "model.bpk holds the average");
        let (resumed, averaged) = trained_values(&dir, &trained);
        assert_eq!(resumed, (vec![1.0, 2.0], vec![5.0]));
        assert_eq!(averaged, Some((vec![3.0, 4.0], vec![5.0])));
        verified(&dir, Purpose::Resume).expect("the trained weights' file is in the manifest");

        // The same step written again without an average leaves no stale trained weights behind.
        let dir = save_folder(root.path(), Weights::Trained(&trained), &optimizer, &state, 2, &[]).unwrap();
        assert!(!dir.join(TRAINED_FILE).exists());
        assert_eq!(trained_values(&dir, &trained), ((vec![1.0, 2.0], vec![5.0]), None));
    }
}
