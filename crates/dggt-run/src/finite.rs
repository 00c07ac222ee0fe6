//! Finding non-finite values (NaN, ±inf) in a module's weights and in the AdamW moments of its parameters.
//!
//! An update that overflows leaves such values behind, and every later forward pass fails on them: the
//! optimiser checks after every update and rolls the step back, and no checkpoint is written with them. Every
//! tensor is reduced to one flag on its device and all flags are read back together, so a check costs one
//! transfer, not one per tensor.

use std::fmt;

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::tensor::{Int, Tensor};

/// What keeps the two AdamW moments of a parameter (the optimiser), to be checked beside its weight.
pub trait Moments {
    /// The first and second moments kept for parameter `id`, once it has been stepped.
    fn moments(&self, id: &ParamId) -> Option<[&Tensor<1>; 2]>;
}

/// Which tensor of a parameter holds a non-finite value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Holder {
    Weight,
    FirstMoment,
    SecondMoment,
}

/// The first tensor, in the module's visiting order, that holds a non-finite value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NonFinite {
    /// The parameter's module path (`gs_head.scratch.layer1_rn.weight`).
    pub parameter: String,
    pub holder: Holder,
}

impl fmt::Display for NonFinite {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = match self.holder {
            Holder::Weight => "weight",
            Holder::FirstMoment => "AdamW first moment of",
            Holder::SecondMoment => "AdamW second moment of",
        };
        write!(f, "{what} `{}`", self.parameter)
    }
}

/// The first weight of `model`, or moment `optimizer` keeps for one of its parameters, that holds a NaN or an
/// infinity; `None` when every value is finite.
pub fn first_non_finite<M: Module>(model: &M, optimizer: Option<&dyn Moments>) -> Option<NonFinite> {
    let mut flags = FiniteFlags { optimizer, path: Vec::new(), checked: Vec::new(), flags: Vec::new() };
    model.visit(&mut flags);
    if flags.flags.is_empty() {
        return None;
    }
    let all_finite = Tensor::cat(flags.flags, 0).into_data().convert::<i64>();
    let position = all_finite.iter::<i64>().position(|finite| finite == 0)?;
    let (parameter, holder) = flags.checked.swap_remove(position);
    Some(NonFinite { parameter, holder })
}

/// One `[1]` flag per checked tensor, 1 when all its values are finite and 0 otherwise, with the tensor it
/// belongs to.
struct FiniteFlags<'a> {
    optimizer: Option<&'a dyn Moments>,
    path: Vec<String>,
    checked: Vec<(String, Holder)>,
    flags: Vec<Tensor<1, Int>>,
}

impl FiniteFlags<'_> {
    fn push<const D: usize>(&mut self, parameter: &str, holder: Holder, tensor: Tensor<D>) {
        if tensor.shape().num_elements() == 0 {
            return;
        }
        self.checked.push((parameter.to_string(), holder));
        self.flags.push(tensor.inner().is_finite().all().int());
    }
}

impl ModuleVisitor for FiniteFlags<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let parameter = self.path.join(".");
        self.push(&parameter, Holder::Weight, param.val());
        if let Some([first, second]) = self.optimizer.and_then(|o| o.moments(&param.id)) {
            self.push(&parameter, Holder::FirstMoment, first.clone());
            self.push(&parameter, Holder::SecondMoment, second.clone());
        }
    }
}
