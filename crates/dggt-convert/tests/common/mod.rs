//! The real driving data the tests and benchmarks read: beside the repository (`../shared/real-data`), or where
//! `$DGGT_REAL_DATA` says. It is licensed for non-commercial research and never copied into the repository;
//! without it the tests fail with this message rather than pass quietly.

use std::path::PathBuf;

pub fn real_data() -> PathBuf {
    dggt_test_data::real_data()
}
