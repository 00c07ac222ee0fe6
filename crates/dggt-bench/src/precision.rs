//! Running the network in a reduced float type: which types a device supports, and a copy of the network
//! whose parameters are cast to one.
//!
//! Support is what burn reports ([`Device::supports_dtype`]: storage, conversion and arithmetic), confirmed by
//! a small probe (a matrix product and an exponential computed in the type and compared with f32), since a
//! type can be declared yet compute garbage on some drivers. A type that fails either is skipped with the
//! reason; nothing falls back silently.

use std::panic::{AssertUnwindSafe, catch_unwind};

use burn::tensor::{DataError, Device, FloatDType, Tensor, TensorData};
use dggt_model::Dggt;

use crate::knobs::Precision;

/// Why a float type cannot run on a device.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PrecisionUnsupported {
    #[error(
        "the device ({device}) does not support {precision} storage, conversion and arithmetic (burn's \
         Device::supports_dtype)"
    )]
    NotDeclared { device: String, precision: Precision },
    #[error("a {precision} probe computation is off by {error:.3} relative to f32")]
    Inaccurate { precision: Precision, error: f64 },
    #[error("a {precision} probe computation failed: {reason}")]
    Failed { precision: Precision, reason: String },
    #[error("a {precision} probe computation panicked: {message}")]
    Panicked { precision: Precision, message: String },
}

/// Why `precision` cannot run on `device`, or `Ok` when it can.
pub fn precision_support(device: &Device, precision: Precision) -> Result<(), PrecisionUnsupported> {
    if precision == Precision::F32 {
        return Ok(());
    }
    if !device.supports_dtype(precision.dtype()) {
        return Err(PrecisionUnsupported::NotDeclared { device: format!("{device:?}"), precision });
    }
    let probe = catch_unwind(AssertUnwindSafe(|| probe_error(device, precision.dtype())));
    match probe {
        Ok(Ok(error)) if error <= 0.05 => Ok(()),
        Ok(Ok(error)) => Err(PrecisionUnsupported::Inaccurate { precision, error }),
        Ok(Err(reason)) => Err(PrecisionUnsupported::Failed { precision, reason: format!("{reason:?}") }),
        Err(panic) => Err(PrecisionUnsupported::Panicked { precision, message: panic_message(&*panic) }),
    }
}

/// Largest relative difference between `exp(a b / 8)` computed in `dtype` and in f32.
fn probe_error(device: &Device, dtype: FloatDType) -> Result<f64, DataError> {
    let n = 16;
    let a: Vec<f32> = (0..n * n).map(|i| ((i * 7 % 17) as f32 - 8.0) / 8.0).collect();
    let b: Vec<f32> = (0..n * n).map(|i| ((i * 5 % 13) as f32 - 6.0) / 6.0).collect();
    let a = Tensor::<2>::from_data(TensorData::new(a, [n, n]), device);
    let b = Tensor::<2>::from_data(TensorData::new(b, [n, n]), device);
    let compute = |a: Tensor<2>, b: Tensor<2>| a.matmul(b).div_scalar(8.0).exp();
    let read = |t: Tensor<2>| t.cast(FloatDType::F32).into_data().convert::<f32>().try_into_vec::<f32>();
    let exact = read(compute(a.clone(), b.clone()))?;
    let reduced = read(compute(a.cast(dtype), b.cast(dtype)))?;
    Ok(exact.iter().zip(&reduced).map(|(&x, &y)| ((x - y).abs() / x.abs().max(1e-3)) as f64).fold(0.0, f64::max))
}

/// The text of a caught panic.
pub fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    if let Some(text) = panic.downcast_ref::<&str>() {
        (*text).to_string()
    } else if let Some(text) = panic.downcast_ref::<String>() {
        text.clone()
    } else {
        "(no message)".into()
    }
}

/// A copy of `model` whose network computes in `precision` ([`Dggt::with_float_dtype`]).
pub fn cast_model(model: &Dggt, precision: Precision) -> Dggt {
    model.clone().with_float_dtype(precision.dtype())
}
