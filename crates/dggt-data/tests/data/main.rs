//! The `dggt-data` integration tests in one binary (one link of the dependency tree instead of one per file).

mod export_errors;
mod real_data;
