//! Crash consistency of training with real kills: a `dggt train` child process killed with SIGKILL after some
//! steps, again inside a checkpoint write (stopped there by the `inside-checkpoint` failpoint), and again
//! mid-run, then resumed to the end, finishes with weights bit-identical to an uninterrupted run's.

use crate::common;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use dggt_run::failpoint::{FAILPOINT_VARIABLE, INSIDE_CHECKPOINT};

const STEPS: u64 = 6;

/// The small configuration, checkpointing every step, written to `dir/train.toml`.
fn write_config(dir: &Path) -> PathBuf {
    let mut config = common::small_config(&dir.join("unused"));
    config.run.steps = STEPS;
    config.run.checkpoint_every = 1;
    config.run.keep_checkpoints = 2;
    common::write_config(dir.join("train.toml"), &config)
}

fn train(config: &Path, out: &Path, resume: bool, failpoint: Option<&str>) -> Child {
    let mut command = Command::new(env!("CARGO_BIN_EXE_dggt"));
    command.args(["train", "--config"]).arg(config).arg("--out").arg(out);
    if resume {
        command.arg("--resume");
    }
    if let Some(name) = failpoint {
        command.env(FAILPOINT_VARIABLE, name);
    }
    command.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("dggt train starts")
}

/// Training steps recorded so far.
fn steps_logged(out: &Path) -> usize {
    std::fs::read_to_string(out.join("metrics.jsonl")).map_or(0, |text| text.matches("\"kind\":\"train\"").count())
}

/// Kills `child` with SIGKILL once `ready` holds (checked every 20 ms, for at most five minutes).
fn kill_when(mut child: Child, what: &str, ready: impl Fn() -> bool) {
    let started = Instant::now();
    while !ready() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the run ended ({status}) before {what}");
        }
        assert!(started.elapsed() < Duration::from_secs(300), "no {what} within five minutes");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
}

/// Waits for the child's stderr to announce that it stopped at `failpoint`, then kills it.
fn kill_at_failpoint(mut child: Child, failpoint: &str) {
    let stderr = child.stderr.take().unwrap();
    let expected = format!("failpoint {failpoint} reached");
    let found = BufReader::new(stderr).lines().map_while(Result::ok).any(|line| line.contains(&expected));
    assert!(found, "the run ended without reaching {failpoint}");
    child.kill().unwrap();
    child.wait().unwrap();
}

/// Waits for a run to end well; returns the step it started at (from its `trained steps A..B` line).
fn finish(child: Child) -> u64 {
    let output = child.wait_with_output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let first = stdout.split("trained steps ").nth(1).and_then(|rest| rest.split("..").next());
    first.and_then(|step| step.parse().ok()).unwrap_or_else(|| panic!("no `trained steps` line in {stdout}"))
}

/// Every tensor of the final checkpoint's weights, by name (the checkpoint of the last step).
fn final_weights(out: &Path) -> Vec<(String, Vec<u8>)> {
    let dir = dggt_run::checkpoint::latest(&out.join("checkpoints"), dggt_run::checkpoint::Purpose::Resume)
        .unwrap()
        .expect("a checkpoint");
    assert!(dir.ends_with(format!("step-{STEPS:08}")), "{}", dir.display());
    common::final_weights(out)
}

#[test]
fn runs_killed_at_any_moment_resume_to_the_weights_of_an_uninterrupted_run() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path());
    let straight = dir.path().join("straight");
    assert_eq!(finish(train(&config, &straight, false, None)), 0);
    let expected = final_weights(&straight);

    let killed = dir.path().join("killed");
    kill_when(train(&config, &killed, false, None), "two steps", || steps_logged(&killed) >= 2);
    kill_at_failpoint(train(&config, &killed, true, Some(INSIDE_CHECKPOINT)), INSIDE_CHECKPOINT);
    let incomplete = std::fs::read_dir(killed.join("checkpoints"))
        .unwrap()
        .filter_map(|e| e.ok())
        .any(|e| e.path().is_dir() && !e.path().join("state.json").exists());
    assert!(incomplete, "the kill inside the checkpoint write leaves an incomplete checkpoint folder");
    let before = steps_logged(&killed);
    kill_when(train(&config, &killed, true, None), "another step", || steps_logged(&killed) > before);
    let resumed_at = finish(train(&config, &killed, true, None));
    assert!(resumed_at >= 2, "the last run resumed at step {resumed_at}, not after the steps already saved");

    let resumed = final_weights(&killed);
    assert_eq!(resumed.len(), expected.len());
    for ((name, bytes), (expected_name, expected_bytes)) in resumed.iter().zip(&expected) {
        assert_eq!(name, expected_name);
        assert!(bytes == expected_bytes, "{name} differs from the uninterrupted run's");
    }
}
