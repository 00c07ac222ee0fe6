//! The `dggt` command integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;
#[allow(dead_code)]
#[path = "../../crates/dggt-convert/tests/nuscenes_scene/mod.rs"]
mod nuscenes_scene;
#[path = "../../crates/dggt-refine-train/tests/common/mod.rs"]
mod refine_common;

mod cli;
mod convert;
mod convert_train;
mod crash_resume;
mod fixture;
mod layering;
mod parity_cli;
mod refine_cli;
mod refine_train_cli;
mod render_pairs;
mod user_files;
