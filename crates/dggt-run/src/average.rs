//! An exponential moving average of a module's trained weights (`[optim.average]`).
//!
//! Late in a run every step still moves the weights by the learning rate times a normalised gradient of one
//! draw of samples, and one unlucky draw can set a run back for a hundred steps just before it ends. The
//! average over the last steps, `a <- decay * a + (1 - decay) * w` after every step from `start_step` on,
//! smooths those moves out. It starts as a copy of the weights at `start_step`, so it needs no bias
//! correction; parameters that are not trained (frozen modules) are copied then and never averaged.
//!
//! The average is a second copy of the weights without autodiff, on the device of the trained ones.
//! Validation scores it, and a checkpoint stores it as the network inference loads
//! ([`crate::checkpoint`]), the trained weights beside it for a resume to continue from.

use std::collections::HashMap;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::tensor::Tensor;

use crate::optim_config::AverageSection;

/// The average of a module's weights over the steps since `start_step`.
#[derive(Debug, Clone)]
pub struct WeightAverage<M> {
    section: AverageSection,
    /// `None` until `start_step` steps have been taken.
    average: Option<M>,
}

impl<M: Module> WeightAverage<M> {
    /// An average as `section` configures it, continuing from `resumed` (a checkpoint's average) when given.
    pub fn new(section: AverageSection, resumed: Option<M>) -> Self {
        Self { section, average: resumed.map(|module| module.valid()) }
    }

    /// Folds the weights `trained` after `steps_taken` optimiser steps into the average; before
    /// `start_step` nothing happens.
    pub fn fold(&mut self, trained: &M, steps_taken: u64) {
        if steps_taken < self.section.start_step {
            return;
        }
        self.average = Some(match self.average.take() {
            None => trained.valid(),
            Some(average) => blend(average, trained, self.section.decay),
        });
    }

    /// The average, once it has started.
    pub fn average(&self) -> Option<&M> {
        self.average.as_ref()
    }
}

/// `decay * average + (1 - decay) * trained` for every trained parameter (matched by id).
fn blend<M: Module>(average: M, trained: &M, decay: f64) -> M {
    let mut weights = TrainedWeights::default();
    trained.visit(&mut weights);
    average.map(&mut Blend { trained: weights.0, decay })
}

/// Every trained parameter of a module, flattened and without autodiff, by id.
#[derive(Default)]
struct TrainedWeights(HashMap<ParamId, Tensor<1>>);

impl ModuleVisitor for TrainedWeights {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let value = param.val();
        if value.is_require_grad() {
            let elements = value.shape().num_elements();
            self.0.insert(param.id, value.inner().reshape([elements]));
        }
    }
}

struct Blend {
    trained: HashMap<ParamId, Tensor<1>>,
    decay: f64,
}

impl ModuleMapper for Blend {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let Some(trained) = self.trained.remove(&param.id) else { return param };
        let decay = self.decay;
        param.map(|average| {
            let dims = average.dims();
            average.mul_scalar(decay).add(trained.reshape(dims).mul_scalar(1.0 - decay))
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use burn::module::{Module, Param};
    use burn::tensor::{Device, Tensor};

    use super::*;

    /// The trained and the frozen parameter's values.
    pub(crate) type Values = (Vec<f32>, Vec<f32>);

    /// A trained parameter and a frozen one.
    #[derive(Module, Debug)]
    pub(crate) struct Pair {
        pub trained: Param<Tensor<1>>,
        pub frozen: Param<Tensor<1>>,
    }

    impl Pair {
        /// Values `trained` (taking gradients) and `frozen` (not), with the ids of `like` when given.
        pub fn new(trained: [f32; 2], frozen: f32, like: Option<&Pair>) -> Self {
            let device = Device::flex().autodiff();
            let value = Tensor::<1>::from_floats(trained, &device).require_grad();
            let fixed = Tensor::<1>::from_floats([frozen], &device);
            let [trained_id, frozen_id] =
                like.map_or([ParamId::new(), ParamId::new()], |p| [p.trained.id, p.frozen.id]);
            Self { trained: Param::initialized(trained_id, value), frozen: Param::initialized(frozen_id, fixed) }
        }

        pub fn values(&self) -> Values {
            let read = |param: &Param<Tensor<1>>| param.val().into_data().try_to_vec::<f32>().unwrap();
            (read(&self.trained), read(&self.frozen))
        }
    }

    #[test]
    fn the_average_starts_as_a_copy_then_folds_in_each_step_and_leaves_frozen_parameters_alone() {
        let mut average = WeightAverage::new(AverageSection { decay: 0.75, start_step: 2 }, None);
        let first = Pair::new([1.0, 2.0], 5.0, None);
        average.fold(&first, 1);
        assert!(average.average().is_none(), "started before start_step");
        average.fold(&first, 2);
        assert_eq!(average.average().unwrap().values(), (vec![1.0, 2.0], vec![5.0]));

        // A frozen parameter never changes in training; one that did is still not averaged.
        let second = Pair::new([3.0, 6.0], 7.0, Some(&first));
        average.fold(&second, 3);
        let averaged = average.average().unwrap();
        assert_eq!(averaged.values(), (vec![1.5, 3.0], vec![5.0]));
        assert!(!averaged.trained.val().device().is_autodiff(), "the average holds no autodiff graph");
        assert_eq!(averaged.trained.id, first.trained.id, "the average keeps the parameters' ids");
    }
}
