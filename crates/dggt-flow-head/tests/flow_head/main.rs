//! The `dggt-flow-head` integration tests in one binary (one link of the dependency tree instead of one per file);
//! `gradients_f64` keeps its own process, whose flex device it sets to f64 before any other use.

#[path = "../common/mod.rs"]
mod common;

mod attention;
mod device_search;
mod gradients;
mod head;
