//! Helpers of the refiner-training tests: the parity data and the tiny run's configuration.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_refine_train::RefineTrainConfig;
use dggt_refine_train::config::{LossSection, LpipsKind, ModelSection, OptimSettings, PairsSection, RunSection};

/// The shared parity folder, which must hold the tiny refiner and the VGG-16 weights.
pub fn parity_dir() -> PathBuf {
    let root = dggt_test_data::Shared::Parity.dir();
    let refiner = root.join("difix_tiny_s1");
    assert!(
        refiner.join("model_difix.pkl").is_file() && root.join("metrics/vgg16_features.safetensors").is_file(),
        "parity data not found under {} (set DGGT_PARITY_DIR to the shared parity folder)",
        root.display()
    );
    root
}

/// The tiny run: learning rate raised from the paper's 2e-5 so that a few steps show progress.
pub fn tiny_config(out_dir: &Path, steps: u64) -> RefineTrainConfig {
    let root = parity_dir();
    let refiner = root.join("difix_tiny_s1");
    RefineTrainConfig {
        model: ModelSection {
            base_dir: refiner.join("base"),
            checkpoint: Some(refiner.join("model_difix.pkl")),
            lora_rank: 4,
            prompt: None,
            prompt_tokens: Vec::new(),
            prompt_tokens_file: Some(refiner.join("inputs.safetensors")),
        },
        pairs: PairsSection {
            rendered: None,
            images: Some(refiner.join("inputs.safetensors")),
            tensors: vec!["image".into(), "ref_image".into()],
            variants: 3,
            held_out: 1,
            max_bad_pairs: 100,
        },
        loss: LossSection {
            l2: 1.0,
            lpips: 1.0,
            gram: 0.5,
            gram_start_step: 0,
            lpips_kind: LpipsKind::Alex,
            lpips_weights: root.join("metrics/lpips_alex.safetensors"),
            gram_vgg: root.join("metrics/vgg16_features.safetensors"),
        },
        optim: OptimSettings { lr: 3e-3, ..OptimSettings::default() },
        run: RunSection {
            steps,
            seed: 7,
            batch: 1,
            out_dir: out_dir.to_path_buf(),
            checkpoint_every: 1000,
            keep_checkpoints: 2,
            validate_every: 0,
        },
        viewer: Default::default(),
    }
}

/// The device the trainer is given (it adds autodiff itself).
pub fn device() -> Device {
    Device::flex()
}
