//! The k-nearest search on a CubeCL device (wgpu; CI: Mesa's software Vulkan driver) against brute force on the
//! host: for every query, `k` distinct valid rows whose distances are the `k` smallest, nearest first, ties in
//! target order; on clouds larger than a cube and a shared tile (64), with coincident and grid points (ties), and
//! `k` from 1 to every point. A query that is not a number keeps the rows `0..k`.
#![cfg(feature = "wgpu")]

use crate::common::Rng;
use burn::tensor::{Device, DeviceKind, Tensor, TensorData};
use dggt_flow_head::neighbours::device::k_nearest;
use dggt_flow_head::neighbours::{SearchPlace, distance_2};

fn wgpu() -> Device {
    Device::wgpu(DeviceKind::default())
}

fn upload(points: &[[f32; 3]], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(points.concat(), [points.len(), 3]), device)
}

/// `n` points: uniform in a 10 m box, or (every third) on a 1 m grid of a few cells, so that ties occur.
fn points(n: usize, rng: &mut Rng) -> Vec<[f32; 3]> {
    (0..n)
        .map(|i| {
            let mut p = [0.0f32; 3];
            for v in &mut p {
                *v = match i % 3 {
                    0 => (rng.unit() * 3.0).floor() as f32,
                    _ => rng.uniform(-5.0, 5.0) as f32,
                };
            }
            p
        })
        .collect()
}

fn device_rows(queries: &[[f32; 3]], targets: &[[f32; 3]], k: usize) -> Vec<usize> {
    let device = wgpu();
    let rows = k_nearest(upload(queries, &device), upload(targets, &device), k);
    assert_eq!(rows.dims(), [queries.len(), k], "k neighbour rows per query");
    rows.into_data().convert::<i64>().try_to_vec::<i64>().unwrap().into_iter().map(|r| r as usize).collect()
}

#[test]
fn the_device_finds_the_nearest_points() {
    let mut rng = Rng::new(5);
    for (queries, targets, k) in [(10, 7, 1), (10, 7, 7), (70, 130, 16), (200, 64, 5), (65, 300, 16), (3, 129, 2)] {
        let (queries, targets) = (points(queries, &mut rng), points(targets, &mut rng));
        let found = device_rows(&queries, &targets, k);
        for (q, (query, rows)) in queries.iter().zip(found.chunks_exact(k)).enumerate() {
            let mut unique = rows.to_vec();
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(unique.len(), k, "query {q}: a row twice: {rows:?}");
            assert!(rows.iter().all(|&r| r < targets.len()), "query {q}: a row out of range: {rows:?}");
            let distances: Vec<f32> = rows.iter().map(|&r| distance_2(targets[r], *query)).collect();
            let mut all: Vec<f32> = targets.iter().map(|p| distance_2(*p, *query)).collect();
            all.sort_by(f32::total_cmp);
            // The device's distances may round differently from the host's (fused multiply-adds), so they are
            // compared within a few f32 steps; exact ties (the grid points) come in target order.
            let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * a.abs().max(b.abs()).max(1.0);
            for (slot, (d, e)) in distances.iter().zip(&all).enumerate() {
                assert!(close(*d, *e), "query {q} slot {slot}: {d}, the {slot}th smallest is {e}");
            }
            for (slot, pair) in distances.windows(2).enumerate() {
                assert!(pair[0] <= pair[1] || close(pair[0], pair[1]), "query {q}: not nearest first at {slot}");
                if pair[0] == pair[1] {
                    assert!(rows[slot] < rows[slot + 1], "query {q}: a tie out of target order: {rows:?}");
                }
            }
        }
    }
}

#[test]
fn a_query_that_is_not_a_number_keeps_the_first_rows() {
    let targets = points(20, &mut Rng::new(6));
    let found = device_rows(&[[f32::NAN, 0.0, 0.0], [0.0, 0.0, 0.0]], &targets, 4);
    assert_eq!(&found[..4], &[0, 1, 2, 3]);
    assert!(found[4..].iter().all(|&r| r < targets.len()));
}

#[test]
fn the_head_searches_on_the_points_device() {
    let device = wgpu();
    assert_eq!(SearchPlace::for_points(&upload(&[[0.0; 3]], &device)), SearchPlace::Device);
    assert_eq!(SearchPlace::for_points(&upload(&[[0.0; 3]], &device.autodiff())), SearchPlace::Device);
    assert_eq!(SearchPlace::for_points(&upload(&[[0.0; 3]], &Device::flex())), SearchPlace::Host);
}
