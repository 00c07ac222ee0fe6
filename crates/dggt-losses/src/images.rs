//! Image layout conventions shared by the losses.
//!
//! At this crate's API an image batch is a `Tensor<4>` of shape `[V, H, W, 3]`: V views, channel-last RGB,
//! linear values in [0, 1], exactly what the project's rasteriser outputs. Masks are `[V, H, W]`. The
//! convolutional networks work on NCHW tensors; [`to_nchw`] is the one conversion, done inside the losses.

use burn::tensor::Tensor;

use crate::error::LossError;

/// Checks that `images` is `[V, H, W, 3]` with `V, H, W > 0` and returns its dims.
pub fn check_rgb(what: &str, images: &Tensor<4>) -> Result<[usize; 4], LossError> {
    let dims = images.dims();
    if dims[3] != 3 || dims[..3].contains(&0) {
        return Err(LossError::InvalidInput(format!("{what} must be [V, H, W, 3] with V, H, W > 0, got {dims:?}")));
    }
    Ok(dims)
}

/// Checks that two image batches are `[V, H, W, 3]` with equal shapes and returns the shape.
pub fn check_rgb_pair(a: &Tensor<4>, b: &Tensor<4>) -> Result<[usize; 4], LossError> {
    let dims = check_rgb("first image batch", a)?;
    let other = check_rgb("second image batch", b)?;
    if dims != other {
        return Err(LossError::InvalidInput(format!("image batches differ in shape: {dims:?} vs {other:?}")));
    }
    Ok(dims)
}

/// `[V, H, W, C]` -> `[V, C, H, W]`.
pub fn to_nchw(images: Tensor<4>) -> Tensor<4> {
    images.permute([0, 3, 1, 2])
}

/// `[V, C, H, W]` -> `[V, H, W, C]`.
pub fn to_nhwc(images: Tensor<4>) -> Tensor<4> {
    images.permute([0, 2, 3, 1])
}

/// Checks that two tensors have the same, non-empty shape.
pub(crate) fn check_same<const D: usize>(what: &str, a: &Tensor<D>, b: &Tensor<D>) -> Result<(), LossError> {
    let (da, db) = (a.dims(), b.dims());
    if da != db {
        return Err(LossError::InvalidInput(format!("{what}: shapes differ: {da:?} vs {db:?}")));
    }
    if da.contains(&0) {
        return Err(LossError::InvalidInput(format!("{what}: empty tensor of shape {da:?}")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Device;

    #[test]
    fn layouts_round_trip_and_shapes_are_checked() {
        let device = Device::flex();
        let x = Tensor::<4>::zeros([2, 5, 7, 3], &device);
        assert_eq!(to_nchw(x.clone()).dims(), [2, 3, 5, 7]);
        assert_eq!(to_nhwc(to_nchw(x.clone())).dims(), [2, 5, 7, 3]);
        assert!(check_rgb_pair(&x, &x).is_ok());
        assert!(check_rgb("x", &Tensor::<4>::zeros([2, 5, 7, 4], &device)).is_err());
        assert!(check_rgb_pair(&x, &Tensor::<4>::zeros([2, 5, 6, 3], &device)).is_err());
    }
}
