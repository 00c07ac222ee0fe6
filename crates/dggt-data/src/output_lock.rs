//! One command at a time per output: a command that writes a folder (or a file) first takes its lock, a file
//! beside it (`.NAME.dggt-lock` in the same parent folder, so that the output's own content is untouched) created
//! exclusively (`O_EXCL`) and holding the process id and the command. A second command into the same output is
//! refused at once, naming the first; the lock goes when its holder ends (dropped, or the process exits after
//! an error). A lock left by a process that no longer runs (killed) is taken over with a warning.
//!
//! Whether a process runs is read from `/proc` (Linux; one that ended but was not waited for does not); elsewhere
//! a left lock is taken for a running process and the error names the file to remove. A process id reused by an
//! unrelated process keeps a left lock held; the error says which process holds it, so the file can be removed
//! by hand. Two commands taking over the same
//! left lock in the same instant may both proceed: the take-over is a removal and a new exclusive creation.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// The end of a lock file's name.
pub const LOCK_SUFFIX: &str = ".dggt-lock";

/// Why an output could not be locked.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    #[error(
        "{} is in use by `{command}` (process {pid}): wait for it to end or write elsewhere (its lock: {})",
        output.display(),
        lock.display()
    )]
    Busy { output: PathBuf, lock: PathBuf, pid: u32, command: String },
    #[error(
        "{} is locked by {}, which names no process: remove it if no dggt command is writing there",
        output.display(),
        lock.display()
    )]
    Unreadable { output: PathBuf, lock: PathBuf },
    #[error("{}: cannot take the output's lock: {source}", path.display())]
    Io { path: PathBuf, source: io::Error },
}

/// A held lock on an output; dropping it releases the output.
#[derive(Debug)]
pub struct OutputLock {
    lock: PathBuf,
}

impl OutputLock {
    /// Takes the lock of `output` (a folder or file, existing or not) for `command` (what the error of a second
    /// command names, e.g. `dggt reconstruct`). Paths to the same output through links or `..` share one lock.
    pub fn acquire(output: &Path, command: &str) -> Result<Self, LockError> {
        let lock = lock_path(output)?;
        if let Some(parent) = lock.parent() {
            fs::create_dir_all(parent).map_err(|source| LockError::Io { path: parent.to_path_buf(), source })?;
        }
        // A few rounds: a lock released or taken over between the attempts is tried again.
        for _ in 0..3 {
            match create(&lock, command) {
                Ok(()) => return Ok(Self { lock }),
                Err(error) if error.kind() == io::ErrorKind::AlreadyExists => {}
                Err(source) => return Err(LockError::Io { path: lock, source }),
            }
            match read_holder(&lock)? {
                Holder::Released => {}
                Holder::Nameless => return Err(LockError::Unreadable { output: output.to_path_buf(), lock }),
                Holder::Process { pid, command } if process_runs(pid) => {
                    return Err(LockError::Busy { output: output.to_path_buf(), lock, pid, command });
                }
                Holder::Process { pid, command } => {
                    tracing::warn!(
                        "{}: taking over the lock left by `{command}` (process {pid}, no longer running)",
                        output.display()
                    );
                    match fs::remove_file(&lock) {
                        Ok(()) => {}
                        Err(error) if error.kind() == io::ErrorKind::NotFound => {}
                        Err(source) => return Err(LockError::Io { path: lock, source }),
                    }
                }
            }
        }
        let source = io::Error::other("the lock kept changing hands: another command is starting on the output");
        Err(LockError::Io { path: lock, source })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.lock
    }
}

impl Drop for OutputLock {
    fn drop(&mut self) {
        if let Err(error) = fs::remove_file(&self.lock)
            && error.kind() != io::ErrorKind::NotFound
        {
            tracing::warn!("{}: cannot remove the lock: {error}", self.lock.display());
        }
    }
}

/// The lock file of `output`: `.NAME.dggt-lock` beside the resolved output.
fn lock_path(output: &Path) -> Result<PathBuf, LockError> {
    let resolved =
        crate::confined::resolved(output).map_err(|source| LockError::Io { path: output.to_path_buf(), source })?;
    match (resolved.parent(), resolved.file_name()) {
        (Some(parent), Some(name)) => Ok(parent.join(format!(".{}{LOCK_SUFFIX}", name.to_string_lossy()))),
        _ => Err(LockError::Io {
            path: output.to_path_buf(),
            source: io::Error::new(io::ErrorKind::InvalidInput, "an output needs a name (not a root folder)"),
        }),
    }
}

/// Creates `lock` exclusively, holding this process's id and `command`.
fn create(lock: &Path, command: &str) -> io::Result<()> {
    let mut file = fs::OpenOptions::new().write(true).create_new(true).open(lock)?;
    let written = writeln!(file, "{}\n{command}", std::process::id()).and_then(|()| file.sync_all());
    if written.is_err() {
        // A lock without its holder would read as unreadable: leave none behind.
        let _ = fs::remove_file(lock);
    }
    written
}

/// Who holds a lock file.
enum Holder {
    /// Nobody any more: the file is gone.
    Released,
    Process {
        pid: u32,
        command: String,
    },
    /// The file names no process (being written this instant, or damaged).
    Nameless,
}

/// Who holds the lock file `lock`: the process id and command it holds.
fn read_holder(lock: &Path) -> Result<Holder, LockError> {
    let text = match fs::read_to_string(lock) {
        Ok(text) => text,
        Err(error) if error.kind() == io::ErrorKind::NotFound => return Ok(Holder::Released),
        Err(source) => return Err(LockError::Io { path: lock.to_path_buf(), source }),
    };
    let mut lines = text.lines();
    let pid = lines.next().and_then(|line| line.trim().parse::<u32>().ok());
    Ok(match pid {
        Some(pid) => Holder::Process { pid, command: lines.next().unwrap_or("a dggt command").to_string() },
        None => Holder::Nameless,
    })
}

/// Whether a process with id `pid` runs: on Linux, whether `/proc/PID` exists and is not a zombie (a process
/// that ended and was not yet waited for); elsewhere assumed.
fn process_runs(pid: u32) -> bool {
    if !cfg!(target_os = "linux") {
        return true;
    }
    match fs::read_to_string(Path::new("/proc").join(pid.to_string()).join("stat")) {
        // `PID (COMMAND) STATE ...`: the state follows the command's closing parenthesis.
        Ok(stat) => stat.rsplit_once(')').is_none_or(|(_, rest)| !rest.trim_start().starts_with('Z')),
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_of_the_same_output_is_refused_naming_the_first_until_it_is_released() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let first = OutputLock::acquire(&out, "dggt reconstruct").unwrap();
        assert_eq!(first.path(), dir.path().canonicalize().unwrap().join(".out.dggt-lock"));
        assert!(!out.exists(), "the output itself is left alone");
        for same in [out.clone(), dir.path().join("./sub/../out")] {
            let error = OutputLock::acquire(&same, "dggt eval").unwrap_err();
            let text = error.to_string();
            assert!(matches!(error, LockError::Busy { pid, .. } if pid == std::process::id()), "{text}");
            assert!(text.contains("`dggt reconstruct`") && text.contains(&std::process::id().to_string()), "{text}");
        }
        let other = OutputLock::acquire(&dir.path().join("out-2"), "dggt eval").unwrap();
        drop(first);
        assert!(!dir.path().join(".out.dggt-lock").exists(), "released");
        let again = OutputLock::acquire(&out, "dggt eval").unwrap();
        drop((again, other));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_lock_left_by_a_process_that_ended_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("run");
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let ended = child.id();
        child.wait().unwrap();
        let lock = dir.path().join(".run.dggt-lock");
        std::fs::write(&lock, format!("{ended}\ndggt train\n")).unwrap();
        let taken = OutputLock::acquire(&out, "dggt train").unwrap();
        let holder = std::fs::read_to_string(taken.path()).unwrap();
        assert_eq!(holder, format!("{}\ndggt train\n", std::process::id()));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_process_that_ended_unwaited_for_does_not_run() {
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let zombie = child.id();
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert!(!process_runs(zombie), "ended, not yet waited for");
        child.wait().unwrap();
        assert!(process_runs(std::process::id()));
    }

    #[test]
    fn a_lock_naming_no_process_is_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let lock = dir.path().join(".out.dggt-lock");
        std::fs::write(&lock, "garbled").unwrap();
        let error = OutputLock::acquire(&dir.path().join("out"), "dggt edit").unwrap_err().to_string();
        assert!(error.contains(".out.dggt-lock") && error.contains("names no process"), "{error}");
        assert_eq!(std::fs::read_to_string(&lock).unwrap(), "garbled", "left as it is");
    }
}
