//! Two-layer perceptron with exact (erf) GELU (`fc1 -> GELU -> fc2`), the head's encodings and its update.

use burn::module::Module;
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::activation::gelu;
use burn::tensor::{Device, Tensor};

/// How the output layer starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputInit {
    /// burn's default (uniform in `+-1/sqrt(fan_in)`).
    Random,
    /// Weights and bias zero: the perceptron outputs exactly zero until trained.
    Zero,
}

#[derive(Module, Debug)]
pub struct Mlp {
    pub fc1: Linear,
    pub fc2: Linear,
}

impl Mlp {
    pub fn new(input: usize, hidden: usize, output: usize, init: OutputInit, device: &Device) -> Self {
        let fc2 = match init {
            OutputInit::Random => LinearConfig::new(hidden, output),
            OutputInit::Zero => LinearConfig::new(hidden, output).with_initializer(Initializer::Zeros),
        };
        Self { fc1: LinearConfig::new(input, hidden).init(device), fc2: fc2.init(device) }
    }

    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        self.fc2.forward(gelu(self.fc1.forward(x)))
    }
}
