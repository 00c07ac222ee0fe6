//! The `dggt-flow-head` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod attention;
mod device_search;
mod gradients;
mod gradients_f64;
mod head;
