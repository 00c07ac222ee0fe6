//! The `dggt-bench` integration tests in one binary (one link of the dependency tree instead of one per file).

mod bench_sweep;
mod bench_units;
