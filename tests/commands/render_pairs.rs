//! The pair generator on a tiny reconstruction run (`configs/tiny-overfit.toml` on the bundled fixture, its
//! network as initialised): the targets of a sample rendered at frames that are not among its inputs, paired
//! with the export's images and an input view as the reference; the pairs file and a folder of shards
//! round-trip; the refiner trains on rendered pairs in its reference-view mode.
//!
//! It joins the DGGT trainer (the reconstruction run) and the refiner's trainer, so it lives with the
//! workspace's tests rather than with either crate's; the refiner's tiny run is the refiner-training tests'.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_refine_train::RefineTrainer;
use dggt_refine_train::pair_files::{PairFiles, shard_path, write_pairs};
use dggt_refine_train::render_pairs::{Reconstruction, render_pairs};
use dggt_run::Start;
use dggt_train::{TrainConfig, Trainer};

use crate::refine_common::{device, tiny_config};

fn reconstruction_run(out: &Path) -> Trainer {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut config = TrainConfig::load(&repo.join("configs/tiny-overfit.toml")).expect("tiny-overfit.toml loads");
    // 5-6 inputs and one target per input: every target lies between the inputs.
    (config.sampler.min_inputs, config.sampler.max_inputs) = (5, 6);
    (config.sampler.targets_per_input, config.sampler.target_margin) = (1, 0);
    Trainer::new(config.unattended(out), vec![Device::flex()], Start::Fresh).expect("the run builds")
}

/// What the run renders pairs from.
fn reconstruction(run: &Trainer) -> Reconstruction<'_> {
    Reconstruction {
        model: run.model(),
        objective: run.objective(),
        sampling: run.sampling(),
        preprocess: &run.config().data.preprocess,
    }
}

#[test]
fn targets_between_the_inputs_are_rendered_and_paired_with_the_truth_and_an_input() {
    let run_dir = tempfile::tempdir().unwrap();
    let run = reconstruction_run(run_dir.path());
    let sample = run.sample(0).unwrap();
    let pairs = render_pairs(reconstruction(&run), [0], &Device::flex()).unwrap();
    assert_eq!(pairs.len(), sample.targets.len(), "one pair per target view");
    let inputs: Vec<Vec<f32>> = sample.inputs.iter().map(|v| v.image.data.clone()).collect();
    for (rendered, target) in pairs.iter().zip(&sample.targets) {
        assert!(!sample.sample.input_frames.contains(&rendered.frame), "frame {} is an input", rendered.frame);
        assert_eq!((rendered.frame, rendered.camera), (target.frame, target.camera));
        let pair = &rendered.pair;
        let size = &target.image.size;
        assert_eq!((pair.render.height, pair.render.width), (size.height as usize, size.width as usize));
        assert_eq!(pair.target.values, target.image.data, "the target is the export's image");
        assert_ne!(pair.render.values, pair.target.values, "the render is the reconstruction's, not the truth");
        let reference = pair.reference.as_ref().expect("a reference view");
        assert!(inputs.contains(&reference.values), "the reference is one of the sample's input views");
    }

    let file = run_dir.path().join("pairs.safetensors");
    write_pairs(&pairs, &file).unwrap();
    assert_eq!(PairFiles::open(&file).unwrap().read_all().unwrap(), pairs, "the pairs file round-trips");

    // A folder of shards reads as its files' pairs in name order, whatever else it holds.
    let shards = run_dir.path().join("shards");
    std::fs::create_dir(&shards).unwrap();
    let (first, second) = pairs.split_at(1);
    write_pairs(second, &shard_path(&shards, 10)).unwrap();
    write_pairs(first, &shard_path(&shards, 9)).unwrap();
    std::fs::write(shards.join("notes.txt"), "not a pair file").unwrap();
    assert_eq!(PairFiles::open(&shards).unwrap().read_all().unwrap(), pairs);
    let empty = run_dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let message = PairFiles::open(&empty).unwrap_err().to_string();
    assert!(message.contains("empty") && message.contains("without pair files"), "{message}");
}

#[test]
fn the_refiner_trains_on_rendered_pairs_with_their_reference_views() {
    let run_dir = tempfile::tempdir().unwrap();
    let run = reconstruction_run(run_dir.path());
    let pairs = render_pairs(reconstruction(&run), [0, 1], &Device::flex()).unwrap();
    let file = run_dir.path().join("pairs.safetensors");
    write_pairs(&pairs, &file).unwrap();

    let out = tempfile::tempdir().unwrap();
    let mut config = tiny_config(out.path(), 2);
    config.pairs.images = None;
    config.pairs.rendered = Some(file);
    let mut trainer = RefineTrainer::new(config, device(), Start::Fresh).unwrap();
    let training = trainer.pairs();
    assert!((0..training.train_len()).all(|i| training.train(i).unwrap().reference.is_some()));
    for _ in 0..2 {
        let record = trainer.step().unwrap();
        assert!(record.loss.is_finite() && record.grad_norm.is_some(), "{record:?}");
    }
    let validation = trainer.validate().unwrap();
    assert!(validation.refined_psnr.is_finite() && validation.render_psnr.is_finite(), "{validation:?}");
}
