//! Float addition into a buffer shared by many units: `buffer[index] += value` as one atomic step. WGSL (and so
//! every device reached through it, Mesa's software Vulkan driver included) has no float atomics; there the add
//! is a compare-and-swap loop on the `u32` bits of the `f32`. Which one a device gets is [`FloatAtomics::of`];
//! kernels are generic over [`FloatAdd`] and launched with the matching implementation.

use burn_cubecl::cubecl;
use cubecl::features::AtomicUsage;
use cubecl::ir::{FloatKind, Type};
use cubecl::prelude::*;

/// `buffer[index] += value` for buffers of `f32` bits, whatever the slot type.
#[cube]
pub trait FloatAdd: Send + Sync + 'static {
    type Slot: CubePrimitive;

    /// `buffer[index] += value` (nothing when `value` is zero).
    fn add(buffer: &Tensor<Atomic<Self::Slot>>, index: usize, value: f32);
}

/// Native `f32` atomic add.
pub struct NativeAdd;

/// Compare-and-swap on the `u32` bits of an `f32`.
pub struct SwapAdd;

#[cube]
impl FloatAdd for NativeAdd {
    type Slot = f32;

    fn add(buffer: &Tensor<Atomic<f32>>, index: usize, value: f32) {
        if value != 0.0 {
            buffer[index].fetch_add(value);
        }
    }
}

#[cube]
impl FloatAdd for SwapAdd {
    type Slot = u32;

    fn add(buffer: &Tensor<Atomic<u32>>, index: usize, value: f32) {
        if value != 0.0 {
            let mut current = buffer[index].load();
            loop {
                let expected = current;
                let sum = f32::from_bits(expected) + value;
                current = buffer[index].compare_exchange_weak(expected, sum.to_bits());
                if current == expected {
                    break;
                }
            }
        }
    }
}

/// Which [`FloatAdd`] a device runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FloatAtomics {
    /// [`NativeAdd`].
    Native,
    /// [`SwapAdd`].
    CompareAndSwap,
}

impl FloatAtomics {
    /// Native where the device adds `f32` atomically, compare-and-swap otherwise.
    pub fn of(client: &cubecl::client::Client) -> Self {
        if client.properties().atomic_type_usage(Type::atomic(FloatKind::F32)).contains(AtomicUsage::Add) {
            Self::Native
        } else {
            Self::CompareAndSwap
        }
    }
}
