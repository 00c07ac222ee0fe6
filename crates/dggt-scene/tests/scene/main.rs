//! The `dggt-scene` integration tests in one binary (one link of the dependency tree instead of one per file).

#[path = "../common/mod.rs"]
mod common;

mod assembly;
mod flow_reach;
mod instance_motion;
mod learnt_flow;
mod saved_scene;
