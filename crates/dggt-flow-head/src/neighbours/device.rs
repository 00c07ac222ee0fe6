//! The k-nearest search on a CubeCL device (features `wgpu` / `cuda`): every query against every target point,
//! so that the moved queries' neighbours are found where the points are, without the host's R*-tree and without
//! reading the positions back for it. A burn backend extension ([`DeviceSearchOps`]) with no gradient: the rows
//! are data, as on the host.
//!
//! Rows come out nearest first, equal distances in target order; a query whose distances all overflow or are not
//! a number keeps the rows `0..k` (valid, distinct, meaningless: the head refuses a non-finite displacement
//! after the iteration anyway).

mod kernel;

use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::tensor::{FloatTensor, IntTensor};
use burn::backend::{Autodiff, Backend, DType, Shape, TensorMetadata, backend_extension};
use burn::tensor::{Int, Tensor};
use burn_cubecl::CubeBackend;
use burn_cubecl::cubecl::prelude::*;
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::ops::numeric::empty_device_dtype;

use kernel::UNITS;

/// `[N, k]`: the rows of the `k` target points (`targets` `[M, 3]`) nearest each query (`queries` `[N, 3]`),
/// on the queries' device; `1 <= k <= M`.
pub fn k_nearest(queries: Tensor<2>, targets: Tensor<2>, k: usize) -> Tensor<2, Int> {
    let rows = <burn::backend::Dispatch as DeviceSearchOps>::k_nearest(
        queries.detach().into_dispatch(),
        targets.detach().into_dispatch(),
        k,
    );
    Tensor::from_dispatch(rows)
}

/// The device search as a burn backend extension (the CubeCL devices, and autodiff over them).
#[backend_extension(
    // burn's `Cube` type: `CubeBackend`, or `Fusion<CubeBackend>` when burn's `fusion` feature is on.
    Cube: cfg(any(feature = "wgpu", feature = "cuda")),
    Autodiff
)]
pub trait DeviceSearchOps: Backend {
    fn k_nearest(queries: FloatTensor<Self>, targets: FloatTensor<Self>, k: usize) -> IntTensor<Self>;
}

impl<B: Backend + DeviceSearchOps, C: CheckpointStrategy> DeviceSearchOps for Autodiff<B, C> {
    fn k_nearest(queries: FloatTensor<Self>, targets: FloatTensor<Self>, k: usize) -> IntTensor<Self> {
        B::k_nearest(queries.into_primitive(), targets.into_primitive(), k)
    }
}

impl DeviceSearchOps for CubeBackend {
    fn k_nearest(queries: FloatTensor<Self>, targets: FloatTensor<Self>, k: usize) -> IntTensor<Self> {
        let points = |tensor: FloatTensor<Self>, what: &str| {
            let shape = tensor.shape();
            assert!(
                tensor.dtype == DType::F32 && shape.num_dims() == 2 && shape[1] == 3,
                "k-nearest search: `{what}` must be [N, 3] f32, got {shape:?} {:?}",
                tensor.dtype
            );
            into_contiguous(tensor)
        };
        let (queries, targets) = (points(queries, "queries"), points(targets, "targets"));
        let (count, targets_len) = (queries.shape()[0], targets.shape()[0]);
        assert!(1 <= k && k <= targets_len, "k-nearest search: {k} neighbours asked of {targets_len} points");
        let client = queries.client.clone();
        let rows = empty_device_dtype(client.clone(), queries.device.clone(), Shape::new([count, k]), DType::I32);
        if count == 0 {
            return rows;
        }
        let cubes = count.div_ceil(UNITS);
        let per_row = cubes.min(65_535);
        kernel::k_nearest_kernel::launch(
            &client,
            CubeCount::new_2d(per_row as u32, cubes.div_ceil(per_row) as u32),
            CubeDim::new_1d(UNITS as u32),
            queries.into_tensor_arg(),
            targets.into_tensor_arg(),
            rows.clone().into_tensor_arg(),
            count as u32,
            targets_len as u32,
            k,
        );
        rows
    }
}

#[cfg(feature = "fusion")]
impl DeviceSearchOps for burn::backend::fusion::Fusion<CubeBackend> {
    fn k_nearest(queries: FloatTensor<Self>, targets: FloatTensor<Self>, k: usize) -> IntTensor<Self> {
        use dggt_cube::fusion::{TensorKind, publish, resolve};
        let rows = CubeBackend::k_nearest(resolve(queries, TensorKind::Float), resolve(targets, TensorKind::Float), k);
        publish(rows, TensorKind::Int)
    }
}
