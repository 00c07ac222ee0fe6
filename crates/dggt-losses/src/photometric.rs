//! Photometric losses between a rendered image and its target: the mean squared error (L2, the paper's
//! reconstruction loss) and the mean absolute error (L1, the release's).
//!
//! Both are means over every element, so they take any layout; the project passes `[V, H, W, 3]`
//! channel-last images with linear values in [0, 1]. The result is a one-element tensor. The L1 gradient at
//! a zero difference is 0 (the subgradient burn's `abs` uses).

use burn::tensor::Tensor;

use crate::error::LossError;
use crate::images::check_same;

/// Mean squared error `mean((rendered - target)^2)`.
pub fn l2<const D: usize>(rendered: Tensor<D>, target: Tensor<D>) -> Result<Tensor<1>, LossError> {
    check_same("l2", &rendered, &target)?;
    Ok((rendered - target).square().mean())
}

/// Mean absolute error `mean(|rendered - target|)`.
pub fn l1<const D: usize>(rendered: Tensor<D>, target: Tensor<D>) -> Result<Tensor<1>, LossError> {
    check_same("l1", &rendered, &target)?;
    Ok((rendered - target).abs().mean())
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    #[test]
    fn values_and_shape_checks() {
        let device = Device::flex();
        let a = Tensor::<2>::from_data(TensorData::new(vec![0.0f32, 1.0, 0.5, 0.25], [2, 2]), &device);
        let b = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 1.0, 0.0, 0.25], [2, 2]), &device);
        let l2 = l2(a.clone(), b.clone()).unwrap().into_scalar::<f32>();
        let l1 = l1(a.clone(), b).unwrap().into_scalar::<f32>();
        assert!((l2 - 1.25 / 4.0).abs() < 1e-7 && (l1 - 1.5 / 4.0).abs() < 1e-7, "{l2} {l1}");
        assert!(super::l1(a, Tensor::zeros([2, 3], &device)).is_err());
    }
}
