//! The `dggt-edit` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod edit_files;
mod edit_truth;
