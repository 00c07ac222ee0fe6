//! Replacing a parameter's value with a new one computed from it (a cast, zeros) that is a leaf of the
//! autodiff graph and trained exactly when the old value was, so that gradients land on the parameter itself.

use burn::module::{ModuleMapper, Param};
use burn::tensor::{FloatDType, Tensor};

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

/// Casts every float parameter of a module to its dtype (`module.map(&mut CastFloats(dtype))`), each a fresh
/// leaf as [`replace_value`] makes it.
pub struct CastFloats(pub FloatDType);

impl ModuleMapper for CastFloats {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let dtype = self.0;
        replace_value(param, |tensor| tensor.cast(dtype))
    }
}
