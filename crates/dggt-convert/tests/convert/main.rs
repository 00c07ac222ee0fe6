//! The `dggt-convert` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;
#[allow(dead_code)]
#[path = "../nuscenes_scene/mod.rs"]
mod nuscenes_scene;

mod argoverse2_real;
mod done_marker;
mod nuscenes_synthetic;
mod nuscenes_untrusted;
mod pandaset_real;
mod waymo_lidar;
mod waymo_real;
