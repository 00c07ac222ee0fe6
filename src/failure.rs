//! What `dggt` prints when a command fails: the error and each of its causes, and no backtrace. An ordinary
//! error (a missing file, a refused flag) is said in words; `RUST_BACKTRACE=1`, often set for the sake of
//! panics, no longer adds a backtrace of the code that noticed it. `RUST_LIB_BACKTRACE=1` asks for the
//! backtrace of errors too (panics keep following `RUST_BACKTRACE`).

use std::backtrace::BacktraceStatus;
use std::fmt::Write;

/// The environment variable that asks for the backtraces of errors (the standard library's name for it).
const BACKTRACE_VARIABLE: &str = "RUST_LIB_BACKTRACE";

/// Whether a failed command prints where in the code the error arose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backtraces {
    Hidden,
    Shown,
}

impl Backtraces {
    /// Shown when `RUST_LIB_BACKTRACE` is set to anything but `0`.
    pub fn from_env() -> Self {
        match std::env::var_os(BACKTRACE_VARIABLE) {
            Some(value) if value != "0" => Self::Shown,
            _ => Self::Hidden,
        }
    }
}

/// `Error: MESSAGE`, then `Caused by:` and the causes, one a line (as anyhow prints them), then the backtrace
/// when it is asked for and was captured.
pub fn describe(error: &anyhow::Error, backtraces: Backtraces) -> String {
    let mut text = format!("Error: {error}");
    let causes: Vec<String> = error.chain().skip(1).map(ToString::to_string).collect();
    match causes.as_slice() {
        [] => {}
        [cause] => {
            let _ = write!(text, "\n\nCaused by:\n    {cause}");
        }
        causes => {
            text.push_str("\n\nCaused by:");
            for (i, cause) in causes.iter().enumerate() {
                let _ = write!(text, "\n    {i}: {cause}");
            }
        }
    }
    let backtrace = error.backtrace();
    if backtraces == Backtraces::Shown && backtrace.status() == BacktraceStatus::Captured {
        let _ = write!(text, "\n\nStack backtrace:\n{backtrace}");
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_is_its_message_and_causes() {
        let error = anyhow::anyhow!("no such file").context("reading a.toml").context("loading the run");
        let text = describe(&error, Backtraces::Hidden);
        assert_eq!(text, "Error: loading the run\n\nCaused by:\n    0: reading a.toml\n    1: no such file");
        assert_eq!(describe(&anyhow::anyhow!("plain"), Backtraces::Shown).lines().next(), Some("Error: plain"));
    }
}
