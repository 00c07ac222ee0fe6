//! What a run never leaves behind, on the bundled fixture (CPU): non-finite weights (an update that makes one
//! is rolled back, a run that keeps diverging stops with a message saying what to change, and no checkpoint
//! holds one), unchecked checkpoints (every file is checked against its checksum: a damaged newest checkpoint
//! gives way to the previous intact one, a damaged checkpoint named directly is an error naming the file), and
//! validation errors that do not say they are validation's.

use std::path::{Path, PathBuf};

use crate::common::{parameters, repo, small_config, weights};
use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor};
use dggt_infer::load_network;
use dggt_model::Dggt;
use dggt_run::checkpoint::{self, MANIFEST_FILE, MODEL_FILE, Purpose, RunState, STATE_FILE};
use dggt_run::{OptimSection, Optimizer};
use dggt_train::records::FailureRecord;
use dggt_train::{DepthFlowMaps, RunOptions, Start, TrainConfig, Trainer};

/// The AdamW state of the master replica as its checkpoint file holds it.
fn optimizer_bytes(trainer: &Trainer, dir: &Path) -> Vec<u8> {
    let path = dir.join("optimizer.bpk");
    trainer.replicas().master().optimizer.save(&path).unwrap();
    std::fs::read(path).unwrap()
}

/// The weights of the checkpoint folder `dir`.
fn checkpoint_weights(dir: &Path) -> Vec<f32> {
    let config = dggt_train::checkpoint::read_model_config(dir).unwrap();
    let model = checkpoint::load_model(dir, Dggt::new(&config, &Device::flex()).unwrap()).unwrap();
    parameters(&model)
}

/// At `lr = 1.0` the first update leaves weights whose outputs overflow, and every later step fails: before,
/// those steps were skipped one after another (nothing could recover), checkpoints were written of the broken
/// weights (pruning the earlier ones) and the run ended on a bare render error from validation. Now the run
/// stops after `optim.max_failed_steps_in_a_row` failed steps with a message saying what to change, writes no
/// checkpoint while steps fail, and keeps only finite weights.
#[test]
fn a_learning_rate_of_one_stops_the_run_as_diverged_without_checkpointing_the_failing_weights() {
    let out = tempfile::tempdir().unwrap();
    let mut config = small_config(out.path(), 10);
    config.optim.lr = 1.0;
    config.optim.groups.values_mut().for_each(|rate| *rate = 1.0);
    config.run.checkpoint_every = 2;
    let limit = config.optim.max_failed_steps_in_a_row;
    let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    let error = trainer.run(RunOptions::default()).expect_err("a diverging run stops").to_string();
    assert!(error.contains("training diverged") && error.contains("in a row made no update"), "{error}");
    assert!(error.contains("optim.lr is 1") && error.contains("--resume"), "{error}");
    let state = trainer.state().clone();
    assert_eq!(state.failed_in_a_row, limit, "{state:?}");
    assert_eq!(state.skipped_steps + state.rolled_back_steps, limit, "{state:?}");
    assert!(weights(&trainer).iter().all(|w| w.is_finite()), "the weights kept are finite");

    let text = std::fs::read_to_string(out.path().join("metrics.jsonl")).unwrap();
    let records: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let failed = records.iter().rev().take(limit as usize);
    assert!(failed.clone().all(|r| r.get("rolled_back").is_some() || r.get("skipped").is_some()), "{text}");
    let first_failed = state.step - limit;
    for entry in std::fs::read_dir(out.path().join("checkpoints")).into_iter().flatten() {
        let dir = entry.unwrap().path();
        if dir.is_dir() {
            let step: u64 = dir.file_name().unwrap().to_str().unwrap()["step-".len()..].parse().unwrap();
            assert!(step <= first_failed, "{} written while steps failed", dir.display());
            let values = checkpoint_weights(&dir);
            assert!(values.iter().all(|w| w.is_finite()), "{} holds non-finite weights", dir.display());
        }
    }
}

/// A rolled-back step leaves the weights and AdamW moments bit for bit as they were, and the next step trains.
#[test]
fn a_rolled_back_step_restores_the_weights_and_the_moments() {
    let out = tempfile::tempdir().unwrap();
    let mut trainer = Trainer::new(small_config(out.path(), 4), vec![Device::flex()], Start::Fresh).unwrap();
    trainer.train_step(&[trainer.sample(0).unwrap()], 1.0, DepthFlowMaps::Skip).unwrap();
    let (before, moments_before) = (weights(&trainer), optimizer_bytes(&trainer, out.path()));
    // A rate past f32's range: every stepped weight becomes infinite or NaN.
    let record = trainer.train_step(&[trainer.sample(1).unwrap()], 1e300, DepthFlowMaps::Skip).unwrap();
    assert!(matches!(&record.failure, Some(FailureRecord::RolledBack(t)) if t.contains('`')), "{record:?}");
    assert!(record.update.is_some_and(|u| u.grad_norm.is_finite()), "{record:?}");
    assert_eq!((trainer.state().rolled_back_steps, trainer.state().failed_in_a_row), (1, 1));
    assert!(before == weights(&trainer), "the weights changed");
    assert!(moments_before == optimizer_bytes(&trainer, out.path()), "the moments changed");
    let record = trainer.train_step(&[trainer.sample(2).unwrap()], 1.0, DepthFlowMaps::Skip).unwrap();
    assert!(record.failure.is_none(), "{record:?}");
    assert_eq!(trainer.state().failed_in_a_row, 0, "a step that trains ends the row");
    assert!(before != weights(&trainer));
}

#[derive(Module, Debug)]
struct OneWeight {
    weight: Param<Tensor<1>>,
}

#[test]
fn a_checkpoint_with_a_non_finite_weight_is_not_written() {
    let root = tempfile::tempdir().unwrap();
    let weight = Tensor::<1>::from_floats([1.0, f32::NAN, 3.0], &Device::flex());
    let module = OneWeight { weight: Param::from_tensor(weight) };
    let optimizer = Optimizer::ungrouped(&OptimSection::default());
    let state = RunState::starting(0, 1);
    let error = checkpoint::save_folder(root.path(), checkpoint::Weights::Trained(&module), &optimizer, &state, 2, &[])
        .unwrap_err()
        .to_string();
    assert!(error.contains("not written") && error.contains("weight `weight`"), "{error}");
    assert_eq!(std::fs::read_dir(root.path()).unwrap().count(), 0, "nothing written");
}

#[test]
fn an_error_of_validation_says_so_and_names_the_step() {
    let data = tempfile::tempdir().unwrap();
    let scene = data.path().join("synth-s0");
    copy_folder(&repo().join("data-fixtures/synth-s0"), &scene);
    // Validation reads the depth cells of its targets for D-RMSE; training without a depth loss does not.
    std::fs::write(scene.join("depth_flows_4/002_0.npy"), b"not a numpy file").unwrap();
    let mut config = small_config(&data.path().join("run"), 1);
    config.data.scene = scene;
    config.loss.depth = 0.0;
    config.data.validation.inputs = vec![0, 4];
    config.data.validation.targets = vec![2];
    let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    let error = trainer.run(RunOptions::default()).expect_err("validation fails").to_string();
    assert!(error.starts_with("validation at step 1: ") && error.contains("002_0.npy"), "{error}");
}

/// A finished two-step run checkpointed after each step: `(run folder, step-1, step-2)`.
fn two_checkpoints(out: &Path) -> (TrainConfig, PathBuf, PathBuf) {
    let mut config = small_config(out, 2);
    config.run.checkpoint_every = 1;
    Trainer::new(config.clone(), vec![Device::flex()], Start::Fresh).unwrap().run(RunOptions::default()).unwrap();
    let root = out.join("checkpoints");
    (config, root.join("step-00000001"), root.join("step-00000002"))
}

/// Flips one bit in each of five bytes spread over the file's second half (the tensor data of a burnpack).
fn flip_bits(path: &Path) {
    let mut bytes = std::fs::read(path).unwrap();
    let len = bytes.len();
    for k in 0..5 {
        bytes[len / 2 + k * (len / 12)] ^= 0x10;
    }
    std::fs::write(path, bytes).unwrap();
}

fn copy_folder(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let target = to.join(path.file_name().unwrap());
        if path.is_dir() { copy_folder(&path, &target) } else { std::fs::copy(&path, &target).map(|_| ()).unwrap() }
    }
}

/// The issue this guards against: five flipped bits in `model.bpk` loaded silently, and a damaged `state.json`
/// in the newest checkpoint was a hard error. Now every kind of damage to the newest checkpoint makes a resume
/// (and inference on the run) fall back to the previous checkpoint, and naming the damaged one directly is an
/// error naming the file.
#[test]
fn a_damaged_newest_checkpoint_gives_way_to_the_previous_intact_one() {
    let original = tempfile::tempdir().unwrap();
    let (config, _, _) = two_checkpoints(original.path());
    type Damage = fn(&Path);
    let damages: [(&str, Damage, Purpose); 4] = [
        (MODEL_FILE, flip_bits, Purpose::Inference),
        (STATE_FILE, |p| std::fs::write(p, b"{ garbage").unwrap(), Purpose::Inference),
        ("optimizer.bpk", |p| std::fs::remove_file(p).unwrap(), Purpose::Resume),
        ("preprocess.json", |p| std::fs::write(p, b"{}").unwrap(), Purpose::Inference),
    ];
    for (file, damage, read_by) in damages {
        let run = tempfile::tempdir().unwrap();
        copy_folder(original.path(), run.path());
        let (step_1, step_2) =
            (run.path().join("checkpoints/step-00000001"), run.path().join("checkpoints/step-00000002"));
        damage(&step_2.join(file));

        let resumed = Trainer::new(config.clone().unattended(run.path()), vec![Device::flex()], Start::Resume);
        assert_eq!(resumed.unwrap().state().step, 1, "{file}: resumed from the previous checkpoint");
        let network = load_network(run.path(), None, &Device::flex()).unwrap();
        let expected = if read_by == Purpose::Inference { &step_1 } else { &step_2 };
        assert_eq!(&network.info.path, expected, "{file}: inference needs only the network's files");

        match load_network(&step_2, None, &Device::flex()) {
            Ok(_) => assert_eq!(read_by, Purpose::Resume, "{file}: a damaged network file loaded"),
            Err(error) => {
                let error = error.to_string();
                assert!(error.contains(&format!("{file}: checksum mismatch")), "{error}");
                assert!(error.contains("step-00000002") && error.contains("damaged"), "{error}");
            }
        }
    }
}

#[test]
fn with_every_checkpoint_damaged_a_resume_is_an_error_naming_each() {
    let run = tempfile::tempdir().unwrap();
    let (config, step_1, step_2) = two_checkpoints(run.path());
    flip_bits(&step_1.join(MODEL_FILE));
    std::fs::remove_file(step_2.join(STATE_FILE)).unwrap();
    let error = Trainer::new(config, vec![Device::flex()], Start::Resume).err().expect("no usable checkpoint");
    let error = error.to_string();
    assert!(error.contains("no usable checkpoint"), "{error}");
    assert!(error.contains("step-00000002 is incomplete") && error.contains("model.bpk: checksum mismatch"), "{error}");
}

/// Checkpoints written before checksums were recorded still load (unverified, with a warning).
#[test]
fn a_checkpoint_without_checksums_still_loads() {
    let run = tempfile::tempdir().unwrap();
    let (config, _, step_2) = two_checkpoints(run.path());
    std::fs::remove_file(step_2.join(MANIFEST_FILE)).unwrap();
    let resumed = Trainer::new(config, vec![Device::flex()], Start::Resume).unwrap();
    assert_eq!(resumed.state().step, 2);
    assert_eq!(load_network(&step_2, None, &Device::flex()).unwrap().info.path, step_2);
}
