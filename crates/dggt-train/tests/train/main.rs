//! The `dggt-train` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod checkpoint_safety;
mod communication_volume;
mod datasets;
mod full_size_configs;
mod training;
