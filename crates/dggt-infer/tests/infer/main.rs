//! The `dggt-infer` integration tests in one binary (one link of the dependency tree instead of one per file).

mod forward;
mod fresh_weights;
mod reduced_precision;
