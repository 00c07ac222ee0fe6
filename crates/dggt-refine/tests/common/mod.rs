//! The refiner's reference vectors for the tests: the shared parity folder's `difix_tiny_s1`
//! ([`dggt_test_data::parity`]). Missing vectors fail the test.

use std::path::PathBuf;

pub fn vectors_dir() -> PathBuf {
    dggt_test_data::parity("difix_tiny_s1")
}
