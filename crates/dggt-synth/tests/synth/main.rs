//! The `dggt-synth` integration tests in one binary (one link of the dependency tree instead of one per file).

mod edit;
mod export;
mod variants;
