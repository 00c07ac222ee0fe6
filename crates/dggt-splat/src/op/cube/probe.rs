//! Single device stages on host data, for the integration tests: the radix sort of intersection keys and the
//! list ranges cut from it, and the prefix sum they rest on, which a render only exercises on the keys its scene happens to produce.

use burn::backend::DispatchDevice;
use burn::backend::ops::IntTensorOps;
use burn::tensor::TensorData;
use burn_cubecl::ops::into_data_sync;
use burn_cubecl::tensor::CubeTensor;
use burn_cubecl::{CubeBackend, CubeDevice};

use super::{arg, bin, element_launch, lists, radix, scan, zeroed};
use burn::backend::DType;

/// Intersections sorted on the device, read back.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SortedIntersections {
    /// The list of each sorted entry.
    pub lists: Vec<u32>,
    /// The input position of each sorted entry (the payload sorted along).
    pub order: Vec<u32>,
    /// Each list's range `[ranges[2 l], ranges[2 l + 1])` of the sorted entries (`[0, 0)` when empty).
    pub ranges: Vec<u32>,
}

fn cube_device(device: &burn::tensor::Device) -> CubeDevice {
    match device.as_dispatch() {
        DispatchDevice::Cube(device) => device.clone(),
        other => panic!("splat: not a CubeCL device: {other:?}"),
    }
}

fn upload(device: &CubeDevice, mut values: Vec<u32>) -> CubeTensor {
    let len = values.len().max(1);
    values.resize(len, 0);
    CubeBackend::int_from_data(TensorData::new(values, [len]), device)
}

fn download(tensor: CubeTensor, len: usize) -> Vec<u32> {
    into_data_sync(tensor).iter::<u32>().take(len).collect()
}

/// Sorts entries `(lists[i], depths[i])` (`lists[i] < list_count`, depths positive) by list then depth with
/// the rasteriser's radix sort, carrying each entry's position, and cuts the list ranges, on a CubeCL device.
pub fn sort_intersections(
    device: &burn::tensor::Device,
    lists: &[u32],
    depths: &[f32],
    list_count: usize,
) -> SortedIntersections {
    assert_eq!(lists.len(), depths.len(), "one depth per entry");
    let device = cube_device(device);
    let len = lists.len();
    let keys = upload(&device, lists.to_vec());
    let depth_bits = upload(&device, depths.iter().map(|d| d.to_bits()).collect());
    let positions = upload(&device, (0..len as u32).collect());
    let (sorted, order) =
        radix::sort_by_two_keys(&device, keys, depth_bits, positions, len, lists::bits_for(list_count), 32);
    let ranges = zeroed(&device, 2 * list_count, DType::U32);
    if len > 0 {
        let client = device.client();
        let (cubes, dim) = element_launch(&client, len);
        bin::ranges_kernel::launch(&client, cubes, dim, arg(&sorted), arg(&ranges), len as u32);
    }
    SortedIntersections {
        lists: download(sorted, len),
        order: download(order, len),
        ranges: download(ranges, 2 * list_count),
    }
}

/// The exclusive prefix sum of `values` (`len + 1` entries, the last the total) with the rasteriser's
/// multi-level scan, on a CubeCL device.
pub fn prefix_sums(device: &burn::tensor::Device, values: &[u32]) -> Vec<u32> {
    let device = cube_device(device);
    let input = upload(&device, values.to_vec());
    download(scan::exclusive_scan(&device, &input, values.len()), values.len() + 1)
}
