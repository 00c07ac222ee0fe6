//! Training on datasets rather than one scene: six synthetic scenes in two export layouts, two held out; the
//! run draws only training scenes, validates on the held-out ones and resumes exactly; a scene whose images are
//! corrupt is skipped sample by sample and counted, and past `data.max_bad_samples` the run stops; a starting
//! checkpoint that does not cover the network is refused with the names of what it lacks.

use crate::common;
use crate::common::{repo, weights};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_data::{DatasetSpec, ExportVariant, HeldOut};
use dggt_objective::{DepthFlowMaps, StepBatch};
use dggt_train::{RunOptions, Start, TrainConfig, Trainer};

/// `count` synthetic scenes `root/000, 001, ...` in `variant`, 10 frames of one camera.
fn scenes(root: &Path, variant: ExportVariant, seeds: std::ops::Range<u64>) {
    for (i, seed) in seeds.enumerate() {
        let config = dggt_synth::SynthConfig { seed, frames: 10, cameras: 1, width: 64, height: 48 };
        dggt_synth::synthesize(&config, &root.join(format!("{i:03}")), variant, dggt_synth::Sweeps::Skip).unwrap();
    }
}

/// The shared LPIPS-Alex weights: the linear layers and the AlexNet features.
fn lpips_alex() -> (PathBuf, PathBuf) {
    let parity = dggt_test_data::Shared::Parity.dir();
    let files = (
        parity.join("metrics/lpips_alex.safetensors"),
        parity.join("metrics/alexnet_features_torchvision_names.safetensors"),
    );
    for file in [&files.0, &files.1] {
        assert!(file.is_file(), "{} not found: set DGGT_PARITY_DIR to the shared parity folder", file.display());
    }
    files
}

fn dataset(root: PathBuf, held_out: &[&str]) -> DatasetSpec {
    let held_out = HeldOut::Scenes(held_out.iter().map(|s| s.to_string()).collect());
    DatasetSpec { root: Some(root), held_out, ..DatasetSpec::default() }
}

/// The overfit configuration made small, on `datasets`, validating at positions 0/3/6 with targets 1/4.
fn config(datasets: Vec<DatasetSpec>, out: &Path, steps: u64) -> TrainConfig {
    let mut config = TrainConfig::load(&repo().join("configs/tiny-overfit.toml")).unwrap();
    config.data.datasets = datasets;
    config.data.frames = None;
    config.data.preprocess.target_width = 56;
    config.data.workers = 1;
    config.sampler.min_inputs = 4;
    config.sampler.max_inputs = 4;
    config.sampler.window = 8;
    config.render.render_inputs = false;
    config.optim.warmup_steps = 2;
    config.run.steps = steps;
    let mut config = config.unattended(out);
    config.data.validation.inputs = vec![0, 3, 6];
    config.data.validation.targets = vec![1, 4];
    config
}

fn records(out: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(out.join("metrics.jsonl")).unwrap();
    text.lines().map(|line| serde_json::from_str(line).unwrap()).collect()
}

#[test]
fn a_multiscene_run_trains_on_its_scenes_validates_on_held_out_ones_and_resumes_exactly() {
    let data = tempfile::tempdir().unwrap();
    scenes(&data.path().join("waymo"), ExportVariant::Waymo, 20..23);
    scenes(&data.path().join("nuscenes"), ExportVariant::NuScenes, 30..33);
    let datasets = vec![dataset(data.path().join("waymo"), &["002"]), dataset(data.path().join("nuscenes"), &["000"])];

    let straight = tempfile::tempdir().unwrap();
    let mut scored = config(datasets.clone(), straight.path(), 4);
    let (linear, alexnet) = lpips_alex();
    scored.data.validation.lpips_weights = Some(linear);
    scored.data.validation.lpips_backbone = Some(alexnet);
    let mut trainer = Trainer::new(scored, vec![Device::flex()], Start::Fresh).unwrap();
    assert_eq!(trainer.index().scenes.len(), 6);
    let summary = trainer.run(RunOptions::default()).unwrap();
    let expected = weights(&trainer);
    let validation = summary.validation.expect("validation at the end");
    let validated: Vec<&str> = validation.scenes.iter().map(|s| s.scene.as_str()).collect();
    assert_eq!(validated, ["waymo/002", "nuscenes/000"]);
    assert!(validation.scenes.iter().all(|s| s.psnr.is_finite() && s.psnr > 5.0), "{validation:?}");
    for scene in &validation.scenes {
        assert!(scene.d_rmse.is_some_and(|d| d.is_finite() && d >= 0.0), "D-RMSE from depth_flows_4: {scene:?}");
        assert!(scene.lpips.is_some_and(|l| (0.0..2.0).contains(&l)), "LPIPS: {scene:?}");
    }
    assert_eq!(validation.views.len(), 4, "two targets of one camera in each of two scenes");
    let logged = records(straight.path()).into_iter().find(|r| r["kind"] == "validation").unwrap();
    assert!(logged["lpips"].is_f64() && logged["d_rmse"].is_f64(), "{logged}");
    let drawn: BTreeSet<String> = records(straight.path())
        .iter()
        .filter(|r| r["kind"] == "train")
        .flat_map(|r| {
            r["scenes"].as_array().unwrap().iter().map(|s| s.as_str().unwrap().to_owned()).collect::<Vec<_>>()
        })
        .collect();
    let training = ["nuscenes/001", "nuscenes/002", "waymo/000", "waymo/001"];
    assert_eq!(drawn, training.into_iter().map(String::from).collect(), "one epoch draws each training scene once");
    assert!(straight.path().join("scene-index.json").is_file());

    let split = tempfile::tempdir().unwrap();
    let mut first =
        Trainer::new(config(datasets.clone(), split.path(), 4), vec![Device::flex()], Start::Fresh).unwrap();
    assert_eq!(first.run(RunOptions { stop_after: Some(2), ..RunOptions::default() }).unwrap().final_step, 2);
    drop(first);
    let mut resumed = Trainer::new(config(datasets, split.path(), 4), vec![Device::flex()], Start::Resume).unwrap();
    resumed.run(RunOptions::default()).unwrap();
    assert!(expected == weights(&resumed), "the resumed run ends with other weights");
}

/// Cuts every image of `scene` to its first half: the header (and size) still reads, the pixels do not.
fn truncate_images(scene: &Path) {
    for entry in std::fs::read_dir(scene.join("images")).unwrap() {
        let path = entry.unwrap().path();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    }
}

#[test]
fn a_scene_with_corrupt_images_is_skipped_sample_by_sample_and_counted() {
    let data = tempfile::tempdir().unwrap();
    scenes(&data.path().join("waymo"), ExportVariant::Waymo, 40..43);
    truncate_images(&data.path().join("waymo/001"));
    let datasets = vec![dataset(data.path().join("waymo"), &[])];

    let out = tempfile::tempdir().unwrap();
    let mut trainer =
        Trainer::new(config(datasets.clone(), out.path(), 3), vec![Device::flex()], Start::Fresh).unwrap();
    let bad = (0..3).map(|k| trainer.sample(k).unwrap()).find(|s| !s.failures.is_empty()).expect("scene 001 drawn");
    assert!(bad.failures[0].contains("001") && bad.failures[0].contains("images"), "{:?}", bad.failures);
    assert_ne!(bad.scene.root, data.path().join("waymo/001"), "a replacement scene was loaded");
    let summary = trainer.run(RunOptions::default()).unwrap();
    assert_eq!(summary.steps_run, 3);
    assert_eq!(trainer.state().bad_samples, 1, "one epoch of three scenes meets the broken one once");
    let last_step = records(out.path()).into_iter().rfind(|r| r["kind"] == "train").unwrap();
    assert_eq!(last_step["bad_samples"], 1);

    let strict = tempfile::tempdir().unwrap();
    let mut strict_config = config(datasets, strict.path(), 3);
    strict_config.data.max_bad_samples = 0;
    let mut trainer = Trainer::new(strict_config, vec![Device::flex()], Start::Fresh).unwrap();
    let error = trainer.run(RunOptions::default()).unwrap_err().to_string();
    assert!(error.contains("max_bad_samples") && error.contains("001"), "{error}");
    assert!(strict.path().join("checkpoints").is_dir(), "the weights so far are saved before stopping");
}

/// A sample that no scene can give names each scene that failed once: a dataset of one broken scene, drawn
/// again as its own replacement, is one scene that failed, not four with the same error four times.
#[test]
fn a_sample_no_scene_can_give_names_each_failed_scene_once() {
    let data = tempfile::tempdir().unwrap();
    scenes(&data.path().join("waymo"), ExportVariant::Waymo, 60..61);
    truncate_images(&data.path().join("waymo/000"));
    let out = tempfile::tempdir().unwrap();
    let datasets = vec![dataset(data.path().join("waymo"), &[])];
    let trainer = Trainer::new(config(datasets, out.path(), 1), vec![Device::flex()], Start::Fresh).unwrap();
    let Err(error) = trainer.sample(0) else { panic!("no scene loads, yet a sample was drawn") };
    let error = error.to_string();
    assert!(error.contains("1 scene failed to load in 4 attempts: ") && error.contains("000"), "{error}");
    assert_eq!(error.matches("images/").count(), 1, "the scene's error once: {error}");
}

/// A run of this project starts a network that adds a head: the run's parameters are carried over by module
/// path, the head is refused until the configuration lets it start fresh.
#[test]
fn a_run_of_this_project_starts_a_network_with_an_added_head() {
    let out = tempfile::tempdir().unwrap();
    let config = common::small_config(out.path(), 1);
    let mut trainer = Trainer::new(config.clone(), vec![Device::flex()], Start::Fresh).unwrap();
    trainer.run(RunOptions::default()).unwrap();
    let trained = weights(&trainer);
    let device = Device::flex();

    // The same architecture from the run folder: every parameter as trained (and not the seed's fresh draw).
    let same = config.model.architecture();
    let init = dggt_infer::StartingWeights { path: out.path(), may_lack: &[] };
    let started = dggt_infer::fresh_model(&same, Some(init), 7, &device).unwrap();
    assert_eq!(common::parameters(&started), trained, "the run's weights, bit for bit");

    // With a flow head: refused naming it, then accepted with the head fresh and the rest as trained.
    let mut with_head = config.model;
    with_head.flow_head = true;
    let with_head = with_head.architecture();
    let init = dggt_infer::StartingWeights { path: out.path(), may_lack: &[] };
    let Err(error) = dggt_infer::fresh_model(&with_head, Some(init), 7, &device) else { panic!("accepted") };
    let error = error.to_string();
    assert!(error.contains("flow_head.") && error.contains("init_may_lack"), "{error}");
    let allowed = ["flow_head.*".to_string()];
    let init = dggt_infer::StartingWeights { path: out.path(), may_lack: &allowed };
    let started = dggt_infer::fresh_model(&with_head, Some(init), 7, &device).unwrap();
    assert_eq!(common::parameters(&started.aggregator), common::parameters(&trainer.model().aggregator));
    assert!(started.flow_head.is_some());
}

#[test]
fn a_starting_checkpoint_that_does_not_cover_the_network_is_refused_by_name() {
    let weights = dggt_test_data::parity("dggt_tiny_s3_56x70").join("weights.safetensors");
    assert!(weights.is_file(), "parity weights missing: {} (set DGGT_PARITY_DIR)", weights.display());
    let device = Device::flex();
    let tiny = TrainConfig::default().model.architecture();

    // The tiny network's own weights without its Gaussian head: refused, naming the head's parameters...
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(&weights).unwrap();
    let tensors = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let kept: Vec<_> = tensors.tensors().into_iter().filter(|(name, _)| !name.starts_with("gs_head.")).collect();
    let partial = dir.path().join("partial.safetensors");
    safetensors::serialize_to_file(kept, None, &partial).unwrap();
    let init = dggt_infer::StartingWeights { path: &partial, may_lack: &[] };
    let Err(error) = dggt_infer::fresh_model(&tiny, Some(init), 0, &device) else { panic!("accepted") };
    let error = error.to_string();
    assert!(error.contains("gs_head.") && error.contains("init_may_lack"), "{error}");
    // ...and accepted when the configuration allows the head to start fresh.
    let allowed = ["gs_head.*".to_string()];
    let init = dggt_infer::StartingWeights { path: &partial, may_lack: &allowed };
    assert!(dggt_infer::fresh_model(&tiny, Some(init), 0, &device).is_ok());

    // The tiny weights given to the full-size network: every mismatched tensor is named.
    let full = dggt_infer::ModelSection { preset: dggt_model::Preset::Dggt, ..Default::default() }.architecture();
    let init = dggt_infer::StartingWeights { path: &weights, may_lack: &[] };
    let Err(error) = dggt_infer::fresh_model(&full, Some(init), 0, &device) else { panic!("accepted") };
    let error = error.to_string();
    assert!(error.contains("aggregator.patch_embed") && error.contains("network [1024"), "{error}");
    assert!(error.len() < 4000, "the names are listed, not the whole file: {} bytes", error.len());
}

#[test]
fn indexing_excludes_broken_scenes_by_name_and_the_cache_follows_the_folders() {
    use dggt_data::{DatasetIndex, Split};
    let data = tempfile::tempdir().unwrap();
    let root = data.path().join("waymo");
    scenes(&root, ExportVariant::Waymo, 50..53);
    std::fs::remove_file(root.join("001/ego_pose/004.txt")).unwrap();
    std::fs::remove_file(root.join("002/images/007_0.jpg")).unwrap();
    let specs = vec![DatasetSpec { held_out: HeldOut::Fraction(0.4), ..dataset(root.clone(), &[]) }];
    let cache = data.path().join("index.json");
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let progress = |_: usize, _: usize| {
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    };
    let index = DatasetIndex::load_or_build(&specs, 1, &cache, &progress).unwrap();
    assert_eq!(index.scenes.len(), 1);
    assert_eq!(index.scenes[0].frames, 0..10);
    let reasons: Vec<&str> = index.excluded.iter().map(|e| e.reason.as_str()).collect();
    assert!(reasons.iter().any(|r| r.contains("ego_pose") && r.contains("no frame 4")), "{reasons:?}");
    assert!(reasons.iter().any(|r| r.contains("007_0.jpg")), "{reasons:?}");
    assert_eq!(index.split(Split::Validation).count() + index.split(Split::Train).count(), 1);
    assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), 3);

    let again = DatasetIndex::load_or_build(&specs, 1, &cache, &progress).unwrap();
    assert_eq!(again, index);
    assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), 3, "the cache was reused: no scene indexed");
    scenes(&data.path().join("more"), ExportVariant::Waymo, 60..61);
    std::fs::rename(data.path().join("more/000"), root.join("003")).unwrap();
    let grown = DatasetIndex::load_or_build(&specs, 1, &cache, &progress).unwrap();
    assert_eq!(grown.scenes.len(), 2, "a new scene folder invalidates the cache");
}

#[test]
fn exports_without_depth_maps_supervise_depth_with_their_projected_lidar() {
    let data = tempfile::tempdir().unwrap();
    let scene = data.path().join("argoverse2/000");
    let synth = dggt_synth::SynthConfig { seed: 50, frames: 10, cameras: 1, width: 64, height: 48 };
    dggt_synth::synthesize(&synth, &scene, ExportVariant::Argoverse2, dggt_synth::Sweeps::Write).unwrap();
    std::fs::remove_dir_all(scene.join("depth_flows_4")).unwrap();
    let out = tempfile::tempdir().unwrap();
    let trainer = Trainer::new(
        config(vec![dataset(data.path().join("argoverse2"), &[])], out.path(), 1),
        vec![Device::flex()],
        Start::Fresh,
    )
    .unwrap();
    let sample = trainer.sample(0).unwrap();
    let preprocess = &trainer.config().data.preprocess;
    let batch =
        StepBatch::new(&sample, &sample.scene, preprocess, DepthFlowMaps::Inputs, &Device::flex().autodiff()).unwrap();
    for view in &batch.inputs {
        let depth = view.depth_flow.as_ref().expect("lidar depth for every input view");
        assert!(depth.pixels.len() > 20, "{} lidar cells", depth.pixels.len());
        assert!(depth.depths.iter().all(|d| d.is_finite() && *d > 0.0));
        assert!(depth.velocities.is_none(), "lidar carries no flow");
    }
}
