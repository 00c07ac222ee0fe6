//! Where tests and benchmarks find their data. Two kinds exist:
//!
//! - the **bundled fixtures** (`data-fixtures/` in the repository), which the project generates itself;
//! - the **shared data** kept beside the repository, never copied into it: the reference implementations'
//!   parity vectors (`shared/parity`), the released checkpoints' key lists (`shared/reference/checkpoint-keys`)
//!   and real driving logs under non-commercial licences (`shared/real-data`).
//!
//! It also starts MPI jobs the way every multi-rank test does ([`mpi_launcher`]), and times the benchmarks'
//! calls the way each of them reports them ([`median_ms`]).
//!
//! Shared data is looked up as `../shared/...` from the repository or from the nearest folder above it that has
//! one (a worktree or a clone may sit deeper), or where an environment variable says. A test that needs data
//! that is not there fails with a message naming where it looked and the variable to set: it never passes
//! quietly.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Median milliseconds of `runs` timed calls of `run` after one untimed warm-up call.
pub fn median_ms(runs: usize, mut run: impl FnMut()) -> f64 {
    run();
    let mut times: Vec<f64> = (0..runs.max(1))
        .map(|_| {
            let started = std::time::Instant::now();
            run();
            started.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// The repository's root folder (the workspace that holds this crate).
///
/// The path is the one this crate was compiled in. A target folder shared between two checkouts of the same
/// sources can hand a test binary compiled in the other checkout, whose path may be gone; then the root is the
/// nearest folder holding `data-fixtures/` above where cargo runs the test (`CARGO_MANIFEST_DIR` at run time,
/// else the working directory).
pub fn repo_root() -> PathBuf {
    let start = std::env::var_os("CARGO_MANIFEST_DIR").map(PathBuf::from).or_else(|| std::env::current_dir().ok());
    root_from(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."), start.as_deref())
}

/// `compiled` when it still holds the workspace, else the nearest folder at or above `start` that holds
/// `data-fixtures/` (else `compiled`, so that the caller's error names the path it was built with).
fn root_from(compiled: &Path, start: Option<&Path>) -> PathBuf {
    if compiled.join("Cargo.toml").is_file() {
        return compiled.to_path_buf();
    }
    start
        .and_then(|start| start.ancestors().find(|dir| dir.join("data-fixtures").is_dir()))
        .map_or_else(|| compiled.to_path_buf(), Path::to_path_buf)
}

/// The bundled fixture `name` (e.g. `synth-s0`) under `data-fixtures/`.
///
/// # Panics
/// When the folder is missing: the fixtures are part of the repository.
pub fn fixture(name: &str) -> PathBuf {
    let dir = repo_root().join("data-fixtures").join(name);
    assert!(dir.is_dir(), "bundled fixture not found at {}", dir.display());
    dir
}

/// One kind of shared data: its folder under `shared/` and the variable that points elsewhere.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shared {
    /// The reference implementations' parity vectors (`$DGGT_PARITY_DIR`).
    Parity,
    /// The released checkpoints' key lists (`$DGGT_CHECKPOINT_KEYS_DIR`).
    CheckpointKeys,
    /// Real driving logs and their exports (`$DGGT_REAL_DATA`).
    RealData,
}

impl Shared {
    /// The folder's path below `shared/`.
    fn relative(self) -> &'static str {
        match self {
            Self::Parity => "parity",
            Self::CheckpointKeys => "reference/checkpoint-keys",
            Self::RealData => "real-data",
        }
    }

    /// The environment variable that overrides where the folder is.
    pub fn variable(self) -> &'static str {
        match self {
            Self::Parity => "DGGT_PARITY_DIR",
            Self::CheckpointKeys => "DGGT_CHECKPOINT_KEYS_DIR",
            Self::RealData => "DGGT_REAL_DATA",
        }
    }

    /// Where the folder is: the variable's value when set, else `../shared/<relative>` from the nearest folder
    /// at or above the repository's root that has one (the repository's own `../shared` when none has).
    /// Nothing is checked: [`Shared::dir`] checks.
    pub fn locate(self) -> PathBuf {
        if let Some(dir) = std::env::var_os(self.variable()) {
            return PathBuf::from(dir);
        }
        let below = |dir: &Path| dir.join("../shared").join(self.relative());
        let root = repo_root();
        root.ancestors().map(below).find(|dir| dir.is_dir()).unwrap_or_else(|| below(&root))
    }

    /// The folder, which must exist.
    ///
    /// # Panics
    /// When it does not, naming where it looked and the variable to set.
    pub fn dir(self) -> PathBuf {
        let dir = self.locate();
        assert!(
            dir.is_dir(),
            "shared {} not found at {} (set {} to the folder)",
            self.relative(),
            dir.display(),
            self.variable()
        );
        dir
    }

    /// The entry `name` of the folder (a file or a subfolder), which must exist.
    ///
    /// # Panics
    /// When it does not, naming where it looked and the variable to set.
    pub fn entry(self, name: &str) -> PathBuf {
        let path = self.dir().join(name);
        assert!(
            path.exists(),
            "{name} not found in the shared {} folder {} (set {} to the folder that holds it)",
            self.relative(),
            path.parent().unwrap_or(&path).display(),
            self.variable()
        );
        path
    }
}

/// The parity vectors' folder `name` (e.g. `dggt_tiny_s3_56x70`, `metrics`, `difix_tiny_s1`).
///
/// # Panics
/// When it is missing.
pub fn parity(name: &str) -> PathBuf {
    Shared::Parity.entry(name)
}

/// The real driving data's folder.
///
/// # Panics
/// When it is missing.
pub fn real_data() -> PathBuf {
    Shared::RealData.dir()
}

/// `mpirun -np ranks program` as the MPI tests and benchmarks start it on one machine: as root in a container,
/// any number of ranks on any core count, unbound, over the shared-memory and loopback transports only (without
/// the kernel's single-copy mechanism, which containers refuse). Needs Open MPI's `mpirun` on the `PATH`.
pub fn mpi_launcher(ranks: usize, program: impl AsRef<OsStr>) -> Command {
    let mut command = Command::new("mpirun");
    command
        .args(["--allow-run-as-root", "--oversubscribe", "--bind-to", "none", "--mca", "btl", "self,vader"])
        .arg("-np")
        .arg(ranks.to_string())
        .arg(program)
        .env("OMPI_MCA_btl_vader_single_copy_mechanism", "none");
    command
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_repository_root_holds_the_workspace_manifest_and_the_fixtures() {
        assert!(repo_root().join("Cargo.toml").is_file());
        assert!(fixture("synth-s0").join("images").is_dir());
    }

    #[test]
    fn a_root_compiled_in_a_checkout_that_is_gone_is_found_above_where_the_test_runs() {
        let scratch = std::env::temp_dir().join(format!("dggt-test-data-root-{}", std::process::id()));
        let (checkout, member) = (scratch.join("checkout"), scratch.join("checkout/crates/member"));
        std::fs::create_dir_all(checkout.join("data-fixtures")).unwrap();
        std::fs::create_dir_all(&member).unwrap();
        let gone = scratch.join("gone/crates/dggt-test-data/../..");
        assert_eq!(root_from(&gone, Some(&member)), checkout);
        assert_eq!(root_from(&gone, Some(&checkout)), checkout);
        assert_eq!(root_from(&gone, None), gone, "nothing to search from: the compiled path, for the error");
        std::fs::write(checkout.join("Cargo.toml"), "").unwrap();
        assert_eq!(root_from(&checkout, Some(&member)), checkout, "a compiled path that holds the workspace wins");
        std::fs::remove_dir_all(&scratch).unwrap();
    }

    #[test]
    fn each_kind_has_its_own_folder_and_variable() {
        let kinds = [Shared::Parity, Shared::CheckpointKeys, Shared::RealData];
        for (i, a) in kinds.iter().enumerate() {
            for b in &kinds[i + 1..] {
                assert_ne!(a.relative(), b.relative());
                assert_ne!(a.variable(), b.variable());
            }
        }
    }

    #[test]
    #[should_panic(expected = "not found")]
    fn a_missing_entry_fails_naming_it() {
        Shared::Parity.entry("no-such-parity-folder");
    }
}
