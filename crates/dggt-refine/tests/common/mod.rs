//! The refiner's reference vectors for the tests: `$DGGT_PARITY_DIR/difix_tiny_s1` when that variable names the
//! shared parity folder, else `shared/parity/difix_tiny_s1` beside the repository. Missing vectors fail the test.

use std::path::PathBuf;

pub fn vectors_dir() -> PathBuf {
    let root = std::env::var_os("DGGT_PARITY_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/parity"));
    let dir = root.join("difix_tiny_s1");
    assert!(
        dir.join("base").is_dir() && dir.join("model_difix.pkl").is_file(),
        "refiner parity vectors not found at {} (set DGGT_PARITY_DIR to the shared parity folder)",
        dir.display()
    );
    dir
}
