//! Replacing a parameter's value with a new one computed from it (a cast, zeros) that is a leaf of the
//! autodiff graph and trained exactly when the old value was, so that gradients land on the parameter itself.

use burn::module::Param;
use burn::tensor::Tensor;

/// `param` with its value replaced by `value(old)` as a fresh leaf that keeps the old one's `require_grad`.
pub fn replace_value<const D: usize>(
    param: Param<Tensor<D>>,
    value: impl FnOnce(Tensor<D>) -> Tensor<D>,
) -> Param<Tensor<D>> {
    param.map(|old| {
        let trained = old.is_require_grad();
        let new = value(old).detach();
        if trained { new.require_grad() } else { new }
    })
}
