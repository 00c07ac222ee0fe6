//! Copies of device tensors on the host, as `f32`. Reading a tensor back is where a device first reports
//! what went wrong with the work queued before it (out of memory, a lost device), so the copy is fallible and
//! its error names the tensor; nothing is ever replaced by an empty or made-up vector.

use burn::tensor::Tensor;

/// A tensor could not be copied to the host: the device failed, or its values are not convertible to `f32`.
#[derive(Debug, thiserror::Error)]
#[error("{tensor}: cannot be read back from the device: {detail}")]
pub struct ReadBackError {
    /// What the tensor holds, as the caller names it.
    pub tensor: String,
    /// What the device or the conversion said.
    pub detail: String,
}

/// The values of `tensor` in row-major order, converted to `f32`; `name` says what it holds in an error.
pub fn host_f32<const D: usize>(tensor: Tensor<D>, name: &str) -> Result<Vec<f32>, ReadBackError> {
    tensor.try_into_vec_as::<f32>().map_err(|e| ReadBackError { tensor: name.to_owned(), detail: e.to_string() })
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, TensorData};

    use super::*;

    #[test]
    fn values_come_back_in_row_major_order_as_f32() {
        let device = Device::default();
        let tensor = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0], [2, 3]), &device);
        let values = host_f32(tensor.transpose(), "transposed").expect("readable");
        assert_eq!(values, vec![1.0, 4.0, 2.0, 5.0, 3.0, 6.0]);
    }

    #[test]
    fn a_half_precision_tensor_is_widened() {
        let device = Device::default();
        let tensor = Tensor::<1>::from_data(TensorData::new(vec![0.5f32, -2.0], [2]), &device)
            .cast(burn::tensor::FloatDType::F16);
        assert_eq!(host_f32(tensor, "half").expect("readable"), vec![0.5, -2.0]);
    }
}
