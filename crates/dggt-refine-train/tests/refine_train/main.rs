//! The `dggt-refine-train` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod pair_files;
mod refine_config;
mod refine_train;
