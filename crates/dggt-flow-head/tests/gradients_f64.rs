//! The flow head's gradients against central differences with the flex device's default float type set to f64
//! (this test binary's process only): every entry of the four inputs (query and target points and features) and
//! three entries of every parameter, on the clustered clouds of `common` (12 queries, 48 targets) with seeded
//! weights everywhere (the zero-initialised last layer included). Without f32 rounding the step can be 1e-6 and
//! the differences agree with autodiff to ~1e-9 of the tensor's largest gradient entry (seen: <= 3.7e-9;
//! asserted: 1e-7 of the largest entry + 1e-7 of the entry's own size).

mod common;

use std::sync::Once;

use burn::tensor::{DType, Device, FloatDType};
use common::{Tolerance, small_check};

fn device() -> Device {
    static CONFIGURE: Once = Once::new();
    CONFIGURE.call_once(|| {
        let mut device = Device::flex();
        device.configure(FloatDType::F64).expect("configuring the flex device for f64");
    });
    Device::flex().autodiff()
}

const TOLERANCE: Tolerance = Tolerance { step: 1e-6, of_largest: 1e-7, relative: 1e-7 };

#[test]
fn input_gradients_in_f64() {
    let check = small_check(device(), TOLERANCE);
    assert_eq!(check.output().dtype(), DType::F64, "the head runs in f64");
    let worst = check.check_inputs();
    println!("inputs: worst {worst:.2e}");
}

#[test]
fn parameter_gradients_in_f64() {
    let (worst, params) = small_check(device(), TOLERANCE).check_parameters(6);
    println!("parameters: worst {worst:.2e}");
    // Every linear layer's weight and bias (the key has no bias): feature_in, state_in (2), offset_in (2), query,
    // key, value, merge, update (2).
    assert_eq!(params.len(), 21, "{params:?}");
}
