//! Two-layer perceptron with exact (erf) GELU: the feed-forward part of every transformer block and the
//! camera head's pose branch (`fc1 -> GELU -> fc2`).

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::gelu;
use burn::tensor::{Device, Tensor};

#[derive(Module, Debug)]
pub struct Mlp {
    pub fc1: Linear,
    pub fc2: Linear,
}

impl Mlp {
    pub fn new(input: usize, hidden: usize, output: usize, device: &Device) -> Self {
        Self { fc1: LinearConfig::new(input, hidden).init(device), fc2: LinearConfig::new(hidden, output).init(device) }
    }

    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        self.fc2.forward(gelu(self.fc1.forward(x)))
    }
}
