//! What several command-line test files share: the bundled overfit configuration made small enough for a
//! test to train it in seconds, and the file it is written to. Each test file uses
//! some of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use dggt_train::TrainConfig;

pub fn repo() -> PathBuf {
    dggt_test_data::repo_root()
}

/// `configs/tiny-overfit.toml` made small and unattended: two inputs at width 56 drawn from a window of 8
/// frames, a two-step warm-up, outputs under `out_dir`.
pub fn small_config(out_dir: &Path) -> TrainConfig {
    let mut config = TrainConfig::load(&repo().join("configs/tiny-overfit.toml")).unwrap();
    config.data.preprocess.target_width = 56;
    config.sampler.min_inputs = 2;
    config.sampler.max_inputs = 2;
    config.sampler.window = 8;
    config.optim.warmup_steps = 2;
    config.unattended(out_dir)
}

/// Writes `config` as TOML to `path`; returns `path`.
pub fn write_config(path: PathBuf, config: &TrainConfig) -> PathBuf {
    std::fs::write(&path, toml::to_string(config).unwrap()).unwrap();
    path
}

/// Every tensor of the newest resumable checkpoint's weights in the run folder `out`, by name.
pub fn final_weights(out: &Path) -> Vec<(String, Vec<u8>)> {
    let dir = dggt_run::checkpoint::latest(&out.join("checkpoints"), dggt_run::checkpoint::Purpose::Resume)
        .unwrap()
        .expect("a checkpoint");
    let reader = burn_pack::Reader::from_file(dir.join("model.bpk")).unwrap();
    let mut tensors: Vec<(String, Vec<u8>)> = reader
        .into_tensors()
        .unwrap()
        .into_iter()
        .map(|t| {
            let (name, _, _, _, bytes) = t.into_parts().unwrap();
            (name, bytes.to_vec())
        })
        .collect();
    tensors.sort();
    tensors
}
