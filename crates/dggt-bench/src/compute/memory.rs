//! Device memory around a workload, and running one whose failure may be a panic.
//!
//! burn's CubeCL allocators keep the pages they reserve until a clean-up, so the bytes reserved at the end of a
//! workload that started from a clean-up are the most it needed at once, give or take pages released on the
//! way: the figure this module reports. The CPU backends report no pools (`None`).

use std::panic::{AssertUnwindSafe, catch_unwind};

use burn::tensor::Device;

use crate::error::BenchError;
use crate::precision::panic_message;

const MIB: f64 = (1u64 << 20) as f64;

/// The device's allocator, cleaned up when a workload starts.
pub struct DeviceMemory {
    device: Device,
}

impl DeviceMemory {
    /// Releases what the allocator holds for no tensor, so that the workload's reservation starts from its
    /// live tensors alone.
    pub fn start(device: &Device) -> Self {
        device.memory_cleanup();
        Self { device: device.clone() }
    }

    /// Bytes the allocator reserves now, MiB; `None` on a backend without pools.
    pub fn held_mib(&self) -> Option<f64> {
        self.device.memory_pool_usage().map(|usage| usage.bytes_reserved as f64 / MIB)
    }
}

/// Runs `work`; a panic (out of device memory is one on some backends) becomes an error with its message.
pub fn guarded<T>(work: impl FnOnce() -> Result<T, BenchError>) -> Result<T, BenchError> {
    match catch_unwind(AssertUnwindSafe(work)) {
        Ok(result) => result,
        Err(panic) => Err(BenchError::Panicked { doing: "the device", message: panic_message(&*panic) }),
    }
}
