//! The `dggt-eval` integration tests in one binary (one link of the dependency tree instead of one per file).

mod eval_metrics;
mod eval_protocol;
