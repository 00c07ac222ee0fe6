//! The `dggt-parity` integration tests in one binary (one link of the dependency tree instead of one per file).

mod parity;
mod refine_parity;
