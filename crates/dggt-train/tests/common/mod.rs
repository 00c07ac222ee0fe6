//! Helpers shared by the trainer's integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::Tensor;
use dggt_train::{TrainConfig, Trainer};

pub fn repo() -> PathBuf {
    dggt_test_data::repo_root()
}

/// The overfit configuration made small: 56-pixel-wide images, four inputs with one target each between them,
/// learning rate 4e-3 (the recipe the trained-quality bounds of these tests were measured with), no input
/// re-renders.
pub fn small_config(out: &Path, steps: u64) -> TrainConfig {
    let mut config = TrainConfig::load(&repo().join("configs/tiny-overfit.toml")).expect("tiny-overfit.toml loads");
    config.data.preprocess.target_width = 56;
    config.sampler.min_inputs = 4;
    config.sampler.max_inputs = 4;
    config.sampler.targets_per_input = 1;
    config.sampler.target_margin = 0;
    config.optim.lr = 4e-3;
    config.render.render_inputs = false;
    config.optim.warmup_steps = 2;
    config.run.steps = steps;
    config.unattended(out)
}

/// Every float parameter of `model` (the network or one of its modules), flattened in visiting order.
pub fn parameters<M: Module>(model: &M) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.extend(param.val().into_data().convert::<f32>().try_into_vec::<f32>().unwrap());
        }
    }
    let mut collect = Collect(Vec::new());
    model.visit(&mut collect);
    collect.0
}

/// The master replica's parameters.
pub fn weights(trainer: &Trainer) -> Vec<f32> {
    parameters(trainer.model())
}
