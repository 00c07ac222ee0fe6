//! The real driving data the tests and benchmarks read: beside the repository (`../shared/real-data`), or where
//! `$DGGT_REAL_DATA` says. It is licensed for non-commercial research and never copied into the repository;
//! without it the tests fail with this message rather than pass quietly.

use std::path::PathBuf;

pub fn real_data() -> PathBuf {
    let dir = std::env::var_os("DGGT_REAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/real-data"));
    assert!(
        dir.is_dir(),
        "real driving data not found at {} (set DGGT_REAL_DATA to the shared real-data folder)",
        dir.display()
    );
    dir
}
