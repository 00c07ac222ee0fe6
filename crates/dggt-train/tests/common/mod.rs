//! Helpers shared by the trainer's integration tests.
#![allow(dead_code)]

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::Tensor;
use dggt_model::Dggt;
use dggt_train::Trainer;

/// Every float parameter of `model`, flattened in visiting order.
pub fn parameters(model: &Dggt) -> Vec<f32> {
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
