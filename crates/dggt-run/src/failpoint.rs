//! Named places where a run can be made to stop on purpose, so that crash consistency can be tested with real
//! kills: with `DGGT_FAILPOINT=<name>` in the environment, a run that reaches the place prints
//! `failpoint <name> reached` on stderr and waits there until it is killed. A run of several processes can also
//! lose one of them on purpose: `DGGT_FAILPOINT=rank-R-exits-at-step-S` makes rank `R` exit with
//! [`FAILPOINT_EXIT_STATUS`] as step `S` begins ([`exit_before_step`]). Without the variable a failpoint costs
//! one environment lookup.

use std::io::Write;
use std::time::Duration;

/// The environment variable naming the failpoint to stop at.
pub const FAILPOINT_VARIABLE: &str = "DGGT_FAILPOINT";

/// Inside a checkpoint write: after the weights, before the optimiser state, the run state and `latest`.
pub const INSIDE_CHECKPOINT: &str = "inside-checkpoint";

/// The exit status of a process that [`exit_before_step`] ends.
pub const FAILPOINT_EXIT_STATUS: i32 = 86;

/// The failpoint name that makes rank `rank` exit as step `step` begins.
pub fn rank_exit_name(rank: usize, step: u64) -> String {
    format!("rank-{rank}-exits-at-step-{step}")
}

/// Exits the process at once (no unwinding, no cleanup) when `DGGT_FAILPOINT` names
/// [`rank_exit_name`]`(rank, step)`: a rank of a job lost mid-run.
pub fn exit_before_step(rank: usize, step: u64) {
    if std::env::var(FAILPOINT_VARIABLE).is_ok_and(|wanted| wanted == rank_exit_name(rank, step)) {
        eprintln!("failpoint {} reached: exiting", rank_exit_name(rank, step));
        let _ = std::io::stderr().flush();
        std::process::exit(FAILPOINT_EXIT_STATUS);
    }
}

/// Stops here, waiting to be killed, when `DGGT_FAILPOINT` names `name`.
pub fn reached(name: &str) {
    if std::env::var(FAILPOINT_VARIABLE).is_ok_and(|wanted| wanted == name) {
        eprintln!("failpoint {name} reached");
        let _ = std::io::stderr().flush();
        loop {
            std::thread::sleep(Duration::from_secs(60));
        }
    }
}
