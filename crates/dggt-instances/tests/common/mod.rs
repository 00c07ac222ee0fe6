//! Scenes shared by the tests (and the benchmark) of instance finding.

pub mod cars;
