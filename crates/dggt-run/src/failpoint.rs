//! Named places where a run can be made to stop on purpose, so that crash consistency can be tested with real
//! kills: with `DGGT_FAILPOINT=<name>` in the environment, a run that reaches the place prints
//! `failpoint <name> reached` on stderr and waits there until it is killed. Without the variable a failpoint
//! costs one environment lookup.

use std::io::Write;
use std::time::Duration;

/// The environment variable naming the failpoint to stop at.
pub const FAILPOINT_VARIABLE: &str = "DGGT_FAILPOINT";

/// Inside a checkpoint write: after the weights, before the optimiser state, the run state and `latest`.
pub const INSIDE_CHECKPOINT: &str = "inside-checkpoint";

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
