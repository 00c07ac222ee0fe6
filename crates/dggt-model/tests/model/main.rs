//! The `dggt-model` integration tests in one binary (one link of the dependency tree instead of one per file).

mod checkpoint_keys;
mod motion_head;
mod pixel_skip;
