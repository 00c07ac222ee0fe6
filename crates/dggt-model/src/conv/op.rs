//! The host 3x3 convolution as a burn backend extension on the CPU backend (`Flex`), with a hand-written
//! backward under autodiff.
//!
//! burn's own convolution on the CPU builds an im2col matrix for the forward pass and computes the weight
//! gradient as a convolution whose kernel is the whole output gradient (another, larger im2col) and the input
//! gradient as a transposed convolution; [`host`](super::host) computes all three as nine strided matrix
//! products instead. The extension is declared for `Flex` (and autodiff over it) only: [`super::forward`]
//! routes every other device to burn's convolution.

use std::sync::Arc;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, TensorMetadata, backend_extension};
use burn::tensor::{TensorData, try_read_sync};

use super::host::{self, ConvShape};

/// `[N, O, H, W]` from input `[N, C, H, W]`, weight `[O, C, 3, 3]` and bias `[O]` (`f32`), stride 1, zero
/// padding 1.
#[backend_extension(Flex, Autodiff)]
pub trait Conv3x3Ops: Backend {
    fn conv3x3_same(input: FloatTensor<Self>, weight: FloatTensor<Self>, bias: FloatTensor<Self>) -> FloatTensor<Self>;
}

/// The host buffers a backward pass reads.
#[derive(Debug)]
pub struct SavedConv {
    shape: ConvShape,
    input: Vec<f32>,
    weight: Vec<f32>,
}

/// A backend that runs [`host`] on its tensors.
pub trait Conv3x3Kernels: Backend {
    fn conv3x3_forward(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, Arc<SavedConv>);

    /// Input, weight and bias gradients from the output gradient.
    fn conv3x3_backward(saved: &SavedConv, grad_output: FloatTensor<Self>) -> [FloatTensor<Self>; 3];
}

fn read<B: Backend>(tensor: FloatTensor<B>, what: &str) -> Vec<f32> {
    try_read_sync(B::float_into_data(tensor))
        .unwrap_or_else(|| panic!("conv3x3: reading `{what}` cannot complete synchronously"))
        .unwrap_or_else(|e| panic!("conv3x3: reading `{what}` failed: {e:?}"))
        .try_into_vec::<f32>()
        .unwrap_or_else(|e| panic!("conv3x3: `{what}` is not an f32 tensor: {e:?}"))
}

impl Conv3x3Kernels for Flex {
    fn conv3x3_forward(
        input: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
    ) -> (FloatTensor<Self>, Arc<SavedConv>) {
        let device = input.device();
        let [images, channels, height, width] = input.shape().dims();
        let outputs = weight.shape()[0];
        let shape = ConvShape { images, channels, outputs, height, width };
        let (input, weight, bias) =
            (read::<Self>(input, "input"), read::<Self>(weight, "weight"), read::<Self>(bias, "bias"));
        let output = host::forward(shape, &input, &weight, Some(&bias));
        let output = Self::float_from_data(TensorData::new(output, [images, outputs, height, width]), &device);
        (output, Arc::new(SavedConv { shape, input, weight }))
    }

    fn conv3x3_backward(saved: &SavedConv, grad_output: FloatTensor<Self>) -> [FloatTensor<Self>; 3] {
        let device = grad_output.device();
        let ConvShape { images, channels, outputs, height, width } = saved.shape;
        let grad = read::<Self>(grad_output, "output gradient");
        let grads = host::backward(saved.shape, &saved.input, &saved.weight, &grad);
        let tensor =
            |values: Vec<f32>, shape: Vec<usize>| Self::float_from_data(TensorData::new(values, shape), &device);
        [
            tensor(grads.input, vec![images, channels, height, width]),
            tensor(grads.weight, vec![outputs, channels, 3, 3]),
            tensor(grads.bias, vec![outputs]),
        ]
    }
}

impl Conv3x3Ops for Flex {
    fn conv3x3_same(input: FloatTensor<Self>, weight: FloatTensor<Self>, bias: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::conv3x3_forward(input, weight, bias).0
    }
}

/// The autodiff node: parents input, weight and bias; state the host buffers of the forward pass.
#[derive(Debug)]
struct Conv3x3Backward;

impl<B: Backend + Conv3x3Kernels> Backward<B, 3> for Conv3x3Backward {
    type State = Arc<SavedConv>;

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let grad_output = grads.consume::<B>(&ops.node);
        let computed = B::conv3x3_backward(&ops.state, grad_output);
        for (parent, grad) in ops.parents.into_iter().zip(computed) {
            if let Some(node) = parent {
                grads.register::<B>(node.id, grad);
            }
        }
    }
}

impl<B: Backend + Conv3x3Kernels, C: CheckpointStrategy> Conv3x3Ops for Autodiff<B, C> {
    fn conv3x3_same(input: FloatTensor<Self>, weight: FloatTensor<Self>, bias: FloatTensor<Self>) -> FloatTensor<Self> {
        let guards = [input.node(), weight.node(), bias.node()];
        let (input, weight, bias) = (input.into_primitive(), weight.into_primitive(), bias.into_primitive());
        match <Conv3x3Backward as Backward<B, 3>>::prepare::<C>(Conv3x3Backward, guards).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (output, saved) = B::conv3x3_forward(input, weight, bias);
                prep.finish(saved, output)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::conv3x3_forward(input, weight, bias).0),
        }
    }
}
