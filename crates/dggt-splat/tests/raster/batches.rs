//! Views rendered in batches under a lowered buffer cap (feature `wgpu`): the same images, statistics and
//! gradients as one batch, a view beyond the cap in bands of its tile rows with the same results, and a clear
//! error when a single tile row does not fit.

use std::panic::{AssertUnwindSafe, catch_unwind};

use dggt_geom::ImageSize;
use dggt_splat::{Opacities, RasterSettings, RenderSettings, ViewBatch, render_with_stats};

use crate::cube::{DeviceResult, assert_close_to_host, cube_device, render_on_with};
use crate::parity::{Tolerance, check, compare};
use crate::scenes::{LossWeights, Rng, Scene, view_at};
use crate::tensor_op::{camera_tensors, gaussian_tensors};

/// Bytes an intersection takes in each per-entry buffer.
const ENTRY_BYTES: u64 = 4;

/// Gradients of the same lists added in another order by the atomics.
const REORDERED: Tolerance = Tolerance { atol: 1e-6, rtol: 1e-5 };

fn five_views(size: ImageSize) -> ViewBatch {
    let views = (0..5).map(|i| view_at([0.15 * i as f32 - 0.3, 0.05 * i as f32, -0.1], 0.08 * i as f32 - 0.16, size));
    ViewBatch::new(views.collect(), size).unwrap()
}

/// The greedy grouping the rasteriser documents: consecutive views while their intersections fit.
fn batch_count(per_view: &[u64], max_entries: u64) -> usize {
    let (mut batches, mut total) = (0, u64::MAX);
    for &count in per_view {
        if total.saturating_add(count) > max_entries {
            (batches, total) = (batches + 1, 0);
        }
        total += count;
    }
    batches
}

fn assert_same(case: &str, batched: &DeviceResult, whole: &DeviceResult) {
    assert_eq!(batched.colors, whole.colors, "{case}: colours");
    assert_eq!(batched.alpha, whole.alpha, "{case}: alpha");
    assert_eq!(batched.depth, whole.depth, "{case}: depth");
    assert_eq!(batched.stats, whole.stats, "{case}: statistics");
    let (b, w) = (&batched.grads, &whole.grads);
    let all = |_| true;
    check(case, "grad means", compare(&b.means, &w.means, all), REORDERED);
    check(case, "grad quats", compare(&b.quats, &w.quats, all), REORDERED);
    check(case, "grad scales", compare(&b.scales, &w.scales, all), REORDERED);
    check(case, "grad opacities", compare(b.opacities.values(), w.opacities.values(), all), REORDERED);
    check(case, "grad colors", compare(&b.colors, &w.colors, all), REORDERED);
    check(case, "grad background", compare(&b.background, &w.background, all), REORDERED);
}

fn check_batched(case: &str, scene: &Scene, views: &ViewBatch, background: &[f32]) {
    let device = cube_device().autodiff();
    let mut rng = Rng::new(8);
    let weights = LossWeights::random(&mut rng, views.len(), views.size(), scene.channels);
    let whole = render_on_with(&device, scene, views, Some(background), &weights, &RasterSettings::default());
    let per_view: Vec<u64> = whole.stats.iter().map(|s| s.tile_intersections as u64).collect();
    let largest = *per_view.iter().max().unwrap();
    assert!(largest > 100, "{case}: the scene should touch many tiles, got {per_view:?}");
    for entries in [largest, largest + largest / 2, 2 * largest + 1] {
        let batches = batch_count(&per_view, entries);
        let raster = RasterSettings { max_buffer_bytes: Some(entries * ENTRY_BYTES), ..RasterSettings::default() };
        let batched = render_on_with(&device, scene, views, Some(background), &weights, &raster);
        eprintln!("{case}: {per_view:?} intersections, {entries} a batch: {batches} batches");
        assert!(batches >= 2, "{case}: a cap of {entries} intersections should split the views");
        assert_same(&format!("{case}, {batches} batches"), &batched, &whole);
    }
    assert_close_to_host(case, &whole, scene, views, Some(background), &weights);
}

#[test]
fn wgpu_batched_views_render_as_one_batch() {
    let mut rng = Rng::new(31);
    let size = ImageSize::new(45, 29).unwrap();
    let scene = Scene::random(&mut rng, 300, 3, (0.05, 0.4));
    check_batched("shared opacities", &scene, &five_views(size), &[0.2, 0.4, 0.1]);
    let mut scene = Scene::random(&mut rng, 300, 4, (0.05, 0.4));
    scene.opacities = Opacities::PerView(rng.ranges(5 * scene.len(), 0.02, 0.95));
    let background = vec![0.3; scene.channels];
    check_batched("per-view opacities", &scene, &five_views(size), &background);
}

#[test]
fn wgpu_views_beyond_the_buffer_cap_render_in_bands_of_tile_rows_as_one_batch() {
    let device = cube_device().autodiff();
    let mut rng = Rng::new(33);
    // 64x48 pixels: 4 x 3 tiles of 16, so that a view splits into bands of one or two tile rows.
    let size = ImageSize::new(64, 48).unwrap();
    let views = five_views(size);
    let scene = Scene::random(&mut rng, 300, 3, (0.05, 0.4));
    let background = [0.2, 0.4, 0.1];
    let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
    let whole = render_on_with(&device, &scene, &views, Some(&background), &weights, &RasterSettings::default());
    let per_view: Vec<u64> = whole.stats.iter().map(|s| s.tile_intersections as u64).collect();
    let largest = *per_view.iter().max().unwrap();
    assert!(largest > 300, "the scene should touch many tiles, got {per_view:?}");
    // Bands of one or two of the three tile rows, and views split beside views batched whole.
    for entries in [largest * 3 / 4, largest - 1] {
        let raster = RasterSettings { max_buffer_bytes: Some(entries * ENTRY_BYTES), ..RasterSettings::default() };
        let banded = render_on_with(&device, &scene, &views, Some(&background), &weights, &raster);
        let split = per_view.iter().filter(|&&count| count > entries).count();
        eprintln!("{per_view:?} intersections, {entries} a batch: {split} views in bands");
        assert!(split >= 1, "a cap of {entries} intersections should split a view");
        assert_same(&format!("{entries} intersections a batch, {split} views in bands"), &banded, &whole);
    }
}

#[test]
fn wgpu_tile_row_beyond_the_buffer_cap_is_a_clear_error() {
    let device = cube_device();
    let mut rng = Rng::new(32);
    // One row of tiles: the view's intersections are the row's.
    let size = ImageSize::new(32, 16).unwrap();
    let views = five_views(size);
    let scene = Scene::random(&mut rng, 200, 3, (0.05, 0.4));
    let gaussians = gaussian_tensors(&scene, views.len(), &device, false);
    let cameras = camera_tensors(&views, &device);
    let (_, stats) = render_with_stats(&gaussians, &cameras, &RenderSettings::default()).unwrap();
    let largest = stats.iter().map(|s| s.tile_intersections as u64).max().unwrap();
    let cap = (largest - 1) * ENTRY_BYTES;
    let raster = RasterSettings { max_buffer_bytes: Some(cap), ..RasterSettings::default() };
    let settings = RenderSettings { raster, background: None };
    let outcome = catch_unwind(AssertUnwindSafe(|| render_with_stats(&gaussians, &cameras, &settings)));
    let panic = outcome.expect_err("a tile row beyond the cap must be refused");
    let message = panic
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default();
    assert!(message.contains("tile row 0 of view"), "message: {message}");
    assert!(message.contains(&format!("{largest} tile intersections")), "message: {message}");
    assert!(message.contains(&format!("{cap} bytes")), "message: {message}");
}
