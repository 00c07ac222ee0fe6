//! Compositing one tile per cube from shared memory (feature `wgpu`), forward and backward, against the host:
//! one, three and four colour channels, image sizes that are no multiple of the tile size, tiles smaller than
//! the default, tile lists longer than one shared-memory stage, both ways of summing the backward's gradients,
//! and tile sizes no cube can hold.

use dggt_geom::ImageSize;
use dggt_splat::constants::MAX_TILE_SIZE;
use dggt_splat::{Opacities, RasterSettings, RenderSettings, ViewBatch, render};

use crate::cube::{assert_close_to_host_with, cube_device, render_on_with};
use crate::scenes::{LossWeights, Rng, Scene, view_at};
use crate::tensor_op::{camera_tensors, gaussian_tensors};

fn two_views(size: ImageSize) -> ViewBatch {
    ViewBatch::new(vec![view_at([0.0; 3], 0.0, size), view_at([0.3, -0.1, 0.2], 0.2, size)], size).unwrap()
}

fn check_case(case: &str, scene: &Scene, size: ImageSize, tile_size: u32, seed: u64) {
    let device = cube_device().autodiff();
    let views = two_views(size);
    let mut rng = Rng::new(seed);
    let weights = LossWeights::random(&mut rng, views.len(), size, scene.channels);
    let background: Vec<f32> = (0..scene.channels).map(|c| 0.1 + 0.2 * c as f32).collect();
    let raster = RasterSettings { tile_size, ..RasterSettings::default() };
    let result = render_on_with(&device, scene, &views, Some(&background), &weights, &raster);
    assert_close_to_host_with(case, &result, scene, &views, Some(&background), &weights, &raster);
}

#[test]
fn wgpu_tile_cubes_match_the_host_for_one_three_and_four_channels() {
    let mut rng = Rng::new(41);
    for (channels, (width, height)) in [(1, (50, 21)), (3, (33, 47)), (4, (17, 16))] {
        let scene = Scene::random(&mut rng, 250, channels, (0.04, 0.4));
        let size = ImageSize::new(width, height).unwrap();
        check_case(&format!("K = {channels}, {width}x{height}"), &scene, size, 16, 42 + channels as u64);
    }
}

#[test]
fn wgpu_tile_cubes_stage_fewer_footprints_than_units_for_many_channels() {
    // 40 channels: 192 bytes a staged footprint in the backward, so 85 of them fit the 16 KiB stage, fewer
    // than the 256 units of a cube.
    let mut rng = Rng::new(48);
    let scene = Scene::random(&mut rng, 400, 40, (0.03, 0.3));
    check_case("K = 40", &scene, ImageSize::new(36, 20).unwrap(), 16, 49);
}

#[test]
fn wgpu_tile_cubes_match_the_host_with_smaller_tiles_and_per_view_opacities() {
    let mut rng = Rng::new(43);
    let mut scene = Scene::random(&mut rng, 200, 3, (0.04, 0.4));
    scene.opacities = Opacities::PerView(rng.ranges(2 * scene.len(), 0.02, 0.95));
    let size = ImageSize::new(29, 19).unwrap();
    for tile_size in [8, 5, 1] {
        check_case(&format!("tile {tile_size}, per-view opacities"), &scene, size, tile_size, 44);
    }
}

/// Small, faint Gaussians: tile lists of over a thousand entries (several stages of 256), few pixels reaching
/// the transmittance floor, so whole stages are walked forward and backward.
fn long_lists() -> Scene {
    let mut rng = Rng::new(45);
    let mut scene = Scene::random(&mut rng, 3000, 4, (0.02, 0.08));
    scene.opacities = Opacities::Shared(rng.ranges(scene.len(), 0.01, 0.2));
    scene
}

#[test]
fn wgpu_tile_cubes_walk_lists_longer_than_one_stage() {
    check_case("long lists", &long_lists(), ImageSize::new(40, 35).unwrap(), 16, 46);
}

#[test]
fn wgpu_tile_cubes_sum_gradients_per_unit_and_with_compare_and_swap() {
    // The backward's other paths (devices without plane operations, or without float atomics) on whatever
    // device runs the tests: the long-list case again, in a child process of this test binary with the
    // variables that select them set.
    let test = "tile_cubes::wgpu_tile_cubes_walk_lists_longer_than_one_stage";
    let child = std::process::Command::new(std::env::current_exe().expect("the test binary"))
        .args(["--exact", test, "--test-threads=1"])
        .env("DGGT_SPLAT_UNIT_SUMS", "1")
        .env("DGGT_SPLAT_CAS_ATOMICS", "1")
        .output()
        .expect("the test binary runs");
    let output = format!("{}\n{}", String::from_utf8_lossy(&child.stdout), String::from_utf8_lossy(&child.stderr));
    // A renamed test would run nothing and still exit 0: the child must have run exactly that one test.
    assert!(
        child.status.success() && output.contains("test result: ok. 1 passed"),
        "{test} failed (or did not run) with per-unit sums and compare-and-swap adds ({}):\n{output}",
        child.status
    );
}

#[test]
fn tiles_larger_than_a_cube_are_refused_on_every_backend() {
    let size = ImageSize::new(40, 40).unwrap();
    let views = two_views(size);
    let scene = Scene::random(&mut Rng::new(47), 20, 3, (0.1, 0.3));
    let settings = RenderSettings {
        raster: RasterSettings { tile_size: MAX_TILE_SIZE + 1, ..RasterSettings::default() },
        background: None,
    };
    for device in [cube_device(), burn::tensor::Device::flex()] {
        let gaussians = gaussian_tensors(&scene, views.len(), &device, false);
        let error = render(&gaussians, &camera_tensors(&views, &device), &settings).expect_err("refused");
        assert!(error.to_string().contains("tile_size must be in 1..=16, got 17"), "{error}");
    }
}
