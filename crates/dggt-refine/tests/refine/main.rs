//! The `dggt-refine` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod refine_loading;
mod refine_runs;
mod refine_tokenizer;
