//! The trainer end to end on the bundled fixture (CPU): a few dozen steps reduce the loss and raise the target
//! PSNR; a run interrupted and resumed ends with the same weights (and average of the weights) as the
//! uninterrupted one; a loss spike skips its step; a non-finite loss
//! skips the step and leaves the weights untouched; two devices sharing the accumulated samples train like
//! one; training on freshly generated synthetic scenes stays finite; the shipped configurations parse and validate;
//! a configuration's model section describes the network the trainer builds.

use crate::common::{parameters, repo, small_config, weights};

use burn::tensor::Device;
use dggt_model::Dggt;
use dggt_run::checkpoint;
use dggt_run::optim_config::{AverageSection, SpikeSection};
use dggt_train::records::{FailureRecord, ScoredWeights, SkipReason};
use dggt_train::{DepthFlowMaps, RunOptions, Start, TrainConfig, Trainer};

#[test]
fn a_few_dozen_steps_reduce_the_loss_and_raise_target_psnr() {
    let out = tempfile::tempdir().unwrap();
    let mut trainer = Trainer::new(small_config(out.path(), 30), vec![Device::flex()], Start::Fresh).unwrap();
    let summary = trainer.run(RunOptions::default()).unwrap();
    assert_eq!(summary.steps_run, 30);
    assert_eq!(summary.skipped_steps, 0);
    let text = std::fs::read_to_string(out.path().join("metrics.jsonl")).unwrap();
    let records: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let mean = |range: std::ops::Range<usize>, key: &str| {
        range.clone().map(|i| records[i][key].as_f64().unwrap()).sum::<f64>() / range.len() as f64
    };
    let (loss_start, loss_end) = (mean(0..5, "loss"), mean(25..30, "loss"));
    let (psnr_start, psnr_end) = (mean(0..5, "target_psnr"), mean(25..30, "target_psnr"));
    assert!(loss_end < 0.7 * loss_start, "loss {loss_start} -> {loss_end}");
    assert!(psnr_end > psnr_start + 1.0, "target PSNR {psnr_start} -> {psnr_end}");
    assert!(summary.checkpoint.is_some_and(|dir| dir.join("model.bpk").is_file()));
}

#[test]
fn an_interrupted_run_resumes_exactly() {
    let straight = tempfile::tempdir().unwrap();
    let mut trainer = Trainer::new(small_config(straight.path(), 4), vec![Device::flex()], Start::Fresh).unwrap();
    trainer.run(RunOptions::default()).unwrap();
    let expected = weights(&trainer);

    let split = tempfile::tempdir().unwrap();
    let mut first = Trainer::new(small_config(split.path(), 4), vec![Device::flex()], Start::Fresh).unwrap();
    let summary = first.run(RunOptions { stop_after: Some(2), ..RunOptions::default() }).unwrap();
    assert_eq!(summary.final_step, 2);
    drop(first);
    let mut resumed = Trainer::new(small_config(split.path(), 4), vec![Device::flex()], Start::Resume).unwrap();
    assert_eq!(resumed.state().step, 2);
    resumed.run(RunOptions::default()).unwrap();
    let actual = weights(&resumed);
    assert_eq!(expected.len(), actual.len());
    let worst = expected.iter().zip(&actual).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst == 0.0, "resumed weights differ by up to {worst}");
}

/// With `optim.average`, validation scores the average (and the trained weights beside it), checkpoints hold it
/// as the network inference loads (the trained weights beside it), and a resumed run continues both exactly.
#[test]
fn an_interrupted_run_that_averages_its_weights_resumes_both_exactly() {
    let config = |out: &std::path::Path| {
        let mut config = small_config(out, 4);
        config.optim.average = Some(AverageSection { decay: 0.5, start_step: 1 });
        (config.data.validation.inputs, config.data.validation.targets) = (vec![0, 4], vec![2]);
        config
    };
    let straight = tempfile::tempdir().unwrap();
    let mut trainer = Trainer::new(config(straight.path()), vec![Device::flex()], Start::Fresh).unwrap();
    let summary = trainer.run(RunOptions::default()).unwrap();
    let (scored, average) = trainer.scored_weights();
    assert_eq!(scored, ScoredWeights::Average);
    let (expected_trained, expected_average) = (weights(&trainer), parameters(&average));
    assert_ne!(expected_trained, expected_average, "the average is not the trained weights");

    let dir = summary.checkpoint.expect("a checkpoint at the end");
    let blank = || Dggt::new(trainer.model_config(), &Device::flex()).unwrap();
    assert_eq!(parameters(&checkpoint::load_model(&dir, blank()).unwrap()), expected_average, "model.bpk");
    let trained = checkpoint::load_module_file(&dir.join(checkpoint::TRAINED_FILE), blank()).unwrap();
    assert_eq!(parameters(&trained), expected_trained, "trained.bpk");
    let metrics = std::fs::read_to_string(straight.path().join("metrics.jsonl")).unwrap();
    let validations: Vec<&str> = metrics.lines().filter(|line| line.contains(r#""kind":"validation""#)).collect();
    assert_eq!(validations.len(), 2, "the average and the trained weights scored at the end: {validations:?}");
    assert!(validations[0].contains(r#""weights":"average""#), "{}", validations[0]);
    assert!(validations[1].contains(r#""weights":"trained""#), "{}", validations[1]);
    let psnr = |line: &str| serde_json::from_str::<serde_json::Value>(line).unwrap()["psnr"].as_f64().unwrap();
    assert_eq!(summary.validation.map(|v| v.psnr), Some(psnr(validations[0])), "the run reports the average's");
    assert_ne!(psnr(validations[0]), psnr(validations[1]));

    let split = tempfile::tempdir().unwrap();
    let mut first = Trainer::new(config(split.path()), vec![Device::flex()], Start::Fresh).unwrap();
    first.run(RunOptions { stop_after: Some(2), ..RunOptions::default() }).unwrap();
    drop(first);
    let mut resumed = Trainer::new(config(split.path()), vec![Device::flex()], Start::Resume).unwrap();
    resumed.run(RunOptions::default()).unwrap();
    assert!(weights(&resumed) == expected_trained, "the resumed trained weights differ");
    assert!(parameters(&resumed.scored_weights().1) == expected_average, "the resumed average differs");
}

#[test]
fn a_non_finite_loss_skips_the_step_and_keeps_the_weights() {
    let out = tempfile::tempdir().unwrap();
    let mut trainer = Trainer::new(small_config(out.path(), 3), vec![Device::flex()], Start::Fresh).unwrap();
    let before = weights(&trainer);
    let mut sample = trainer.sample(0).unwrap();
    sample.targets[0].image.data[5] = f32::NAN;
    let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
    assert_eq!(record.failure, Some(FailureRecord::Skipped(SkipReason::NonFiniteLoss)), "{record:?}");
    assert_eq!(trainer.state().skipped_steps, 1);
    assert_eq!(before, weights(&trainer));
    // A non-finite input makes every network output non-finite: also a skip, not an error that ends the run.
    let mut sample = trainer.sample(1).unwrap();
    sample.inputs[0].image.data[7] = f32::INFINITY;
    let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
    assert_eq!(record.failure, Some(FailureRecord::Skipped(SkipReason::NonFiniteLoss)), "{record:?}");
    assert_eq!(trainer.state().skipped_steps, 2);
    assert_eq!(before, weights(&trainer));
    // The next, finite step trains.
    let sample = trainer.sample(1).unwrap();
    let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
    assert!(record.finite_loss().is_some(), "{record:?}");
    assert_ne!(before, weights(&trainer));
}

/// With `optim.skip_loss_spikes`, a step whose loss jumps above the recent median times the factor makes no
/// update, is counted apart from divergence, and the next ordinary step trains; the window of recent losses is
/// saved with the run state, so a resumed run judges its steps against the same losses.
#[test]
fn a_loss_spike_skips_the_step_and_the_window_of_losses_survives_a_resume() {
    let out = tempfile::tempdir().unwrap();
    let mut config = small_config(out.path(), 8);
    config.optim.skip_loss_spikes = Some(SpikeSection { factor: 3.0, window: 3 });
    let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    for index in 0..3 {
        let sample = trainer.sample(index).unwrap();
        let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
        assert_eq!(record.failure, None, "step {index}: {record:?}");
    }
    let before = weights(&trainer);
    let mut sample = trainer.sample(3).unwrap();
    sample.targets[0].image.data.iter_mut().for_each(|v| *v = 40.0);
    let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
    assert_eq!(record.failure, Some(FailureRecord::Skipped(SkipReason::LossSpike)), "{record:?}");
    assert!(record.finite_loss().is_some(), "the spike's loss is recorded: {record:?}");
    assert_eq!(before, weights(&trainer), "a spike leaves the weights untouched");
    let state = trainer.state();
    assert_eq!((state.spike_skipped_steps, state.skipped_steps, state.failed_in_a_row), (1, 0, 0));
    assert_eq!(state.recent_losses.len(), 3, "the window keeps the newest three losses, the spike's included");
    let sample = trainer.sample(4).unwrap();
    let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
    assert_eq!(record.failure, None, "{record:?}");
    assert_ne!(before, weights(&trainer));

    let split = tempfile::tempdir().unwrap();
    let config = |out: &std::path::Path| {
        let mut config = small_config(out, 4);
        config.optim.skip_loss_spikes = Some(SpikeSection { factor: 3.0, window: 50 });
        config
    };
    let mut first = Trainer::new(config(split.path()), vec![Device::flex()], Start::Fresh).unwrap();
    first.run(RunOptions { stop_after: Some(2), ..RunOptions::default() }).unwrap();
    let remembered = first.state().recent_losses.clone();
    assert_eq!(remembered.len(), 2);
    drop(first);
    let resumed = Trainer::new(config(split.path()), vec![Device::flex()], Start::Resume).unwrap();
    assert_eq!(resumed.state().recent_losses, remembered, "the resumed run judges against the same losses");
}

/// The pose warm-up's losses (the camera term alone) do not enter the window: the first full steps after it
/// are judged against full losses only, not skipped as spikes.
#[test]
fn the_pose_warm_up_leaves_the_window_of_losses_empty() {
    let out = tempfile::tempdir().unwrap();
    let mut config = small_config(out.path(), 5);
    config.optim.pose_warmup_steps = 3;
    config.optim.skip_loss_spikes = Some(SpikeSection { factor: 1.5, window: 3 });
    let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    for index in 0..5 {
        let sample = trainer.sample(index).unwrap();
        let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
        assert_eq!(record.failure, None, "step {index}: {record:?}");
    }
    assert_eq!(trainer.state().recent_losses.len(), 2, "only the two full steps are remembered");
}

#[test]
fn shipped_configurations_parse_and_validate() {
    let dir = repo().join("configs");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        // `refine-*.toml` configure the refiner's trainer (`dggt-refine-train` checks them).
        let refiner = path.file_name().is_some_and(|n| n.to_string_lossy().starts_with("refine-"));
        if path.extension().is_some_and(|e| e == "toml") && !refiner {
            TrainConfig::load(&path).unwrap_or_else(|e| panic!("{e}"));
            count += 1;
        }
    }
    assert!(count >= 1);
    let bad = tempfile::NamedTempFile::new().unwrap();
    std::fs::write(bad.path(), "[optim]\nlearning_rate = 1.0\n").unwrap();
    let error = TrainConfig::load(bad.path()).unwrap_err().to_string();
    assert!(error.contains("learning_rate"), "{error}");
    let overfit = std::fs::read_to_string(dir.join("tiny-overfit.toml")).unwrap();
    assert!(overfit.contains("\neps2d = "), "the overfit configuration sets render.eps2d");
    let zero_eps2d: String = overfit
        .lines()
        .map(|l| if l.starts_with("eps2d = ") { "eps2d = 0.0\n".into() } else { format!("{l}\n") })
        .collect();
    std::fs::write(bad.path(), zero_eps2d).unwrap();
    let error = TrainConfig::load(bad.path()).unwrap_err().to_string();
    assert!(error.contains("render.eps2d"), "{error}");
    // An empty input range is a configuration error, not a failure of every sample.
    let inverted: String = overfit
        .lines()
        .map(|l| if l.starts_with("min_inputs = ") { "min_inputs = 9\n".into() } else { format!("{l}\n") })
        .collect();
    std::fs::write(bad.path(), inverted).unwrap();
    let error = TrainConfig::load(bad.path()).unwrap_err().to_string();
    let max_inputs = TrainConfig::load(&dir.join("tiny-overfit.toml")).unwrap().sampler.max_inputs;
    assert!(error.contains(&format!("min_inputs (9) exceeds max_inputs ({max_inputs})")), "{error}");
}

#[test]
fn two_devices_each_with_its_own_sample_train_like_one_device_accumulating_both() {
    let run = |devices: Vec<Device>, accumulation: usize| {
        let out = tempfile::tempdir().unwrap();
        let mut config = small_config(out.path(), 2);
        config.optim.accumulation = accumulation;
        let mut trainer = Trainer::new(config, devices, Start::Fresh).unwrap();
        assert_eq!(trainer.samples_per_step(), 2);
        assert_eq!(trainer.state().samples_per_step, 2, "recorded for the checkpoints");
        let summary = trainer.run(RunOptions::default()).unwrap();
        assert_eq!((summary.steps_run, summary.skipped_steps), (2, 0));
        let replicas: Vec<Vec<f32>> = trainer.replicas().iter().map(|r| parameters(&r.model)).collect();
        for (d, replica) in replicas.iter().enumerate().skip(1) {
            assert!(replica == &replicas[0], "replica {d} drifted from the master");
        }
        weights(&trainer)
    };
    let single = run(vec![Device::flex()], 2);
    let split = run(vec![Device::flex(), Device::flex()], 1);
    assert_eq!(single.len(), split.len());
    let initial = {
        let out = tempfile::tempdir().unwrap();
        weights(&Trainer::new(small_config(out.path(), 2), vec![Device::flex()], Start::Fresh).unwrap())
    };
    let moved = initial.iter().zip(&single).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    let worst = single.iter().zip(&split).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(moved > 1e-4, "the steps changed the weights by only {moved}");
    assert!(worst <= 1e-5 * moved.max(1.0), "two devices differ from one by up to {worst} (steps moved {moved})");
}

/// A bounded version of the stability run (docs/BENCHMARKS.md): two freshly generated synthetic scenes, a few
/// dozen steps each at the overfit configuration's learning rate, every step finite and none skipped.
#[test]
fn training_on_varied_synthetic_scenes_stays_finite() {
    for seed in [11, 12] {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene");
        let synth = dggt_synth::SynthConfig { seed, frames: 10, cameras: 1, width: 96, height: 64 };
        dggt_synth::synthesize(&synth, &scene, dggt_data::ExportVariant::Waymo, dggt_synth::Sweeps::Skip).unwrap();
        let mut config = small_config(&dir.path().join("run"), 20);
        config.data.scene = scene;
        config.data.frames = None;
        config.sampler.window = 8;
        let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
        let summary = trainer.run(RunOptions::default()).unwrap();
        assert_eq!((summary.steps_run, summary.skipped_steps), (20, 0), "seed {seed}");
        let text = std::fs::read_to_string(dir.path().join("run/metrics.jsonl")).unwrap();
        for line in text.lines() {
            let record: serde_json::Value = serde_json::from_str(line).unwrap();
            for key in ["loss", "grad_norm", "target_psnr"] {
                assert!(record[key].as_f64().is_some_and(f64::is_finite), "seed {seed}: {key} in {record}");
            }
        }
    }
}

#[test]
fn the_motion_head_starts_at_zero_and_is_trained_by_the_renders() {
    let out = tempfile::tempdir().unwrap();
    let mut config = small_config(out.path(), 3);
    config.model.motion_head = true;
    let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    let output_layer = |trainer: &Trainer| -> Vec<f32> {
        let head = trainer.model().motion_head.as_ref().expect("a motion head");
        head.scratch.output_conv2.out.weight.val().into_data().convert::<f32>().try_into_vec::<f32>().unwrap()
    };
    assert!(output_layer(&trainer).iter().all(|w| *w == 0.0), "a fresh motion head predicts zero");
    trainer.run(RunOptions::default()).unwrap();
    let trained = output_layer(&trainer);
    assert!(trained.iter().all(|w| w.is_finite()) && trained.iter().any(|w| *w != 0.0), "the motion head trained");
}

#[test]
fn the_flow_head_starts_holding_and_waits_for_the_dynamic_head() {
    let out = tempfile::tempdir().unwrap();
    let mut config = small_config(out.path(), 3);
    config.model.flow_head = true;
    config.render.dynamic_motion = dggt_scene::DynamicMotion::Learnt;
    let mut trainer = Trainer::new(config.clone(), vec![Device::flex()], Start::Fresh).unwrap();
    let output_layer = |trainer: &Trainer| -> Vec<f32> {
        let head = trainer.model().flow_head.as_ref().expect("a flow head");
        head.update.fc2.weight.val().into_data().convert::<f32>().try_into_vec::<f32>().unwrap()
    };
    assert!(output_layer(&trainer).iter().all(|w| *w == 0.0), "a fresh flow head predicts zero");
    // A fresh dynamic head marks no pixel dynamic: the flow head has no query, runs on no pair and keeps its
    // zero output while the rest of the network trains (renders along its flow train it once there are queries:
    // `dggt-scene`'s `learnt_flow` tests).
    let before = weights(&trainer);
    trainer.run(RunOptions::default()).unwrap();
    assert!(output_layer(&trainer).iter().all(|w| *w == 0.0), "the flow head trained without queries");
    assert_ne!(weights(&trainer), before, "the network trained");

    // Each without the other is refused, naming the setting.
    let mut without_motion = config.clone();
    without_motion.render.dynamic_motion = dggt_scene::DynamicMotion::Velocity;
    let error = without_motion.validate().unwrap_err().to_string();
    assert!(error.contains("model.flow_head") && error.contains("learnt"), "{error}");
    let mut without_head = config.clone();
    without_head.model.flow_head = false;
    let error = without_head.validate().unwrap_err().to_string();
    assert!(error.contains("render.dynamic_motion") && error.contains("model.flow_head"), "{error}");
    // So are the head's supervision and its shape without a head.
    let mut supervised = without_head;
    supervised.render.dynamic_motion = dggt_scene::DynamicMotion::Velocity;
    supervised.loss.learnt_flow = 0.1;
    let error = supervised.validate().unwrap_err().to_string();
    assert!(error.contains("loss.learnt_flow") && error.contains("model.flow_head"), "{error}");
    let mut shaped = supervised;
    shaped.loss.learnt_flow = 0.0;
    shaped.model.flow.iterations = 1;
    let error = shaped.validate().unwrap_err().to_string();
    assert!(error.contains("model.flow") && error.contains("model.flow_head"), "{error}");
    // The shape reaches the network the trainer builds.
    let mut one_step = config;
    one_step.model.flow.iterations = 1;
    let head = one_step.model.architecture().flow_head.expect("a flow head");
    assert_eq!(head.shape.iterations, 1);
}

#[test]
fn the_flow_loss_teaches_the_gaussian_head_the_scene_flow() {
    let out = tempfile::tempdir().unwrap();
    // The velocity rows start at zero, so the shared features only start to separate moving from still cells
    // once those rows have grown: the term stays near its zero-velocity level for the first few dozen steps.
    let steps = 100;
    let mut config = small_config(out.path(), steps);
    config.model.gaussian_velocity = true;
    config.loss.flow = 1.0;
    config.sampler.targets_per_input = 2;
    let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    let summary = trainer.run(RunOptions::default()).unwrap();
    assert_eq!(summary.skipped_steps, 0);
    let text = std::fs::read_to_string(out.path().join("metrics.jsonl")).unwrap();
    let flow: Vec<f64> = text
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter_map(|r| r["terms"]["flow"].as_f64())
        .collect();
    assert_eq!(flow.len(), steps as usize, "every step has a flow term");
    let mean = |values: &[f64]| values.iter().sum::<f64>() / values.len() as f64;
    let (start, end) = (mean(&flow[..5]), mean(&flow[flow.len() - 5..]));
    assert!(start > 0.0 && end < 0.8 * start, "flow loss {start} -> {end}");

    // Without predicted velocities there is nothing for the flow to supervise.
    let mut config = small_config(out.path(), 1);
    config.loss.flow = 1.0;
    let error = Trainer::new(config, vec![Device::flex()], Start::Fresh).err().expect("an error").to_string();
    assert!(error.contains("loss.flow") && error.contains("gaussian_velocity"), "{error}");
}

#[test]
fn validation_frames_outside_the_scene_are_refused_before_training() {
    let out = tempfile::tempdir().unwrap();
    let mut config = small_config(out.path(), 3);
    config.data.frames = Some([0, 12]);
    config.sampler.window = 12;
    config.data.validation.inputs = vec![0, 4, 8];
    config.data.validation.targets = vec![12];
    let error = Trainer::new(config, vec![Device::flex()], Start::Fresh).err().expect("an error").to_string();
    assert!(error.contains("data.validation") && error.contains("frame 12"), "{error}");
}

#[test]
fn the_model_section_describes_the_network_the_trainer_builds() {
    let out = tempfile::tempdir().unwrap();
    let config = small_config(out.path(), 1);
    let architecture = config.model.architecture();
    assert!(architecture.dpt.pixel_skip, "the overfit configuration turns the pixel skip on");
    assert_eq!(architecture.sky_model.as_ref().map(|sky| sky.resolution), config.model.sky_resolution);
    let trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    assert_eq!(trainer.model_config(), &architecture, "what `--config` gives reconstruct and eval");
}

/// Every setting with a valid range is checked against it, the error naming the key and the range; a run on
/// one scene uses all of `data.frames`, so a range reaching past the fixture's 20 frames is refused too.
#[test]
fn settings_out_of_their_range_are_refused_naming_the_key_and_the_range() {
    let out = tempfile::tempdir().unwrap();
    type Edit = fn(&mut TrainConfig);
    let cases: [(Edit, &str); 16] = [
        (|c| c.optim.weight_decay = -1.0, "optim.weight_decay: must lie in [0, inf), got -1"),
        (|c| c.optim.beta1 = 1.0, "optim.beta1: must lie in [0, 1), got 1"),
        (|c| c.optim.beta2 = -0.1, "optim.beta2: must lie in [0, 1), got -0.1"),
        (|c| c.optim.epsilon = 0.0, "optim.epsilon: must lie in (0, inf), got 0"),
        (|c| c.optim.min_lr_ratio = 2.0, "optim.min_lr_ratio: must lie in [0, 1], got 2"),
        (|c| c.optim.clip_grad_norm = Some(f64::INFINITY), "optim.clip_grad_norm: must lie in (0, inf), got inf"),
        (|c| c.optim.max_failed_steps_in_a_row = 0, "optim.max_failed_steps_in_a_row: must lie in [1, 10000], got 0"),
        (
            |c| c.optim.average = Some(AverageSection { decay: 1.0, start_step: 0 }),
            "optim.average.decay: must lie in (0, 1), got 1",
        ),
        (
            |c| c.optim.average = Some(AverageSection { decay: 0.9, start_step: 1 }),
            "optim.average.start_step: 1 never starts in a run of run.steps = 1",
        ),
        (
            |c| c.optim.skip_loss_spikes = Some(SpikeSection { factor: 1.0, window: 50 }),
            "optim.skip_loss_spikes.factor: must lie in (1, inf), got 1",
        ),
        (
            |c| c.optim.skip_loss_spikes = Some(SpikeSection { factor: 3.0, window: 2 }),
            "optim.skip_loss_spikes.window: must be at least 3, got 2",
        ),
        (|c| c.run.steps = 0, "run.steps: must be at least 1, got 0"),
        (|c| c.run.keep_checkpoints = 0, "run.keep_checkpoints: must be at least 1, got 0"),
        (|c| c.run.time_limit_s = Some(-5.0), "run.time_limit_s: must lie in (0, inf), got -5"),
        (|c| c.data.frames = Some([5, 5]), "data.frames: [5, 5) is empty"),
        (|c| c.data.preprocess.target_width = 50, "data.preprocess: "),
    ];
    for (edit, expected) in cases {
        let mut config = small_config(out.path(), 1);
        edit(&mut config);
        let error = config.validate().expect_err(expected).to_string();
        assert!(error.contains(expected), "{expected} missing from: {error}");
    }
    let mut config = small_config(out.path(), 1);
    config.data.frames = Some([0, 500]);
    let error = Trainer::new(config, vec![Device::flex()], Start::Fresh).err().expect("frames past the scene");
    let error = error.to_string();
    assert!(error.contains("data.frames: [0, 500) reaches outside the frames of"), "{error}");
    assert!(error.contains("synth-s0") && error.contains("an end of at most 20"), "{error}");
}
