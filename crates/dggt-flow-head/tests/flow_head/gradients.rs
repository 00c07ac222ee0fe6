//! The flow head's gradients against central differences in f32, on `Device::flex().autodiff()`: every entry of
//! the four inputs and three entries of every parameter, on the clustered clouds of `common` (12 queries, 48
//! targets, neighbour sets fixed under the step) with seeded weights everywhere, the zero-initialised last layer
//! included.
//!
//! Step 1e-3 as in the workspace's other f32 gradient checks; an entry passes when its error is at most 1e-2 of
//! the tensor's largest gradient entry plus 1e-2 of its own size (seen: <= 1.1e-3 for the inputs, <= 1.8e-3 for
//! the parameters). The f32 rounding of the loss (a sum of 36 terms), divided by the step, bounds the accuracy;
//! `gradients_f64.rs` repeats the check in f64 at ~1e-9.

use crate::common::{Tolerance, small_check};
use burn::tensor::Device;

const TOLERANCE: Tolerance = Tolerance { step: 1e-3, of_largest: 1e-2, relative: 1e-2 };

#[test]
fn input_gradients() {
    let worst = small_check(Device::flex().autodiff(), TOLERANCE).check_inputs();
    println!("inputs: worst {worst:.2e}");
}

#[test]
fn parameter_gradients() {
    let (worst, _) = small_check(Device::flex().autodiff(), TOLERANCE).check_parameters(6);
    println!("parameters: worst {worst:.2e}");
}
