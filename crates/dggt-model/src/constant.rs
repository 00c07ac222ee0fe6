//! Constant tensors the network builds from host values (normalisation statistics, RoPE tables, resampling
//! weights, positional embeddings) in the float type of the activations they meet.
//!
//! Backends do not promote mixed float types (`flex` refuses an f32 operand beside a bf16 one), so a network
//! whose parameters are cast to f16 or bf16 runs end to end only if every constant follows the activations.
//! The values are computed in f32 or f64 on the host and rounded once, on creation.

use burn::tensor::{DType, Device, Tensor, TensorCreationOptions, TensorData};

/// Where, and in which float type, a constant is created.
#[derive(Debug, Clone)]
pub struct ConstantSite {
    pub device: Device,
    pub dtype: DType,
}

impl ConstantSite {
    /// f32 constants on `device`.
    pub fn f32(device: &Device) -> Self {
        Self { device: device.clone(), dtype: DType::F32 }
    }

    /// The device and float type of `tensor`.
    pub fn like<const D: usize>(tensor: &Tensor<D>) -> Self {
        Self { device: tensor.device(), dtype: tensor.dtype() }
    }

    /// `values` (row-major) as a `shape` tensor in this site's float type.
    pub fn tensor<const D: usize>(&self, values: Vec<f32>, shape: [usize; D]) -> Tensor<D> {
        let options = TensorCreationOptions::new(self.device.clone()).with_dtype(self.dtype);
        Tensor::from_data(TensorData::new(values, shape), options)
    }
}
