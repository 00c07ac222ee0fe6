//! Where a GPU's time goes, stage by stage, on request: with the environment variable `DGGT_SPLAT_STAGE_TIMES`
//! set, every forward and backward call waits for the device after each stage and writes one line to standard
//! error with the wall time of each stage in milliseconds, for example (one batch of views, from view 0)
//! `splat forward 2200000x12: project+count 3.45, pair scan 0.72, views 0.. fill of 61293651 1.37, views 0.. radix
//! sort 16.69, views 0.. ranges 0.55, views 0.. composite 2.61 (total 25.38 ms)`.
//!
//! Waiting between stages keeps the device from overlapping them and costs a little each time, so the timed
//! benchmarks run without it; it is a profiler for one call, not a figure to compare with another build. The
//! first mark also waits for the work queued before the call, so that it is not counted in the first stage.

use std::time::Instant;

use burn_cubecl::cubecl::client::Client;
use burn_cubecl::cubecl::future::block_on;

/// The environment variable that turns stage timing on.
const STAGE_TIMES: &str = "DGGT_SPLAT_STAGE_TIMES";

/// The stage times of one call; does nothing unless [`STAGE_TIMES`] is set.
pub struct StageClock {
    /// The client to wait on, when timing is on.
    client: Option<Client>,
    what: String,
    last: Instant,
    stages: Vec<(String, f64)>,
}

impl StageClock {
    /// Starts the clock of one call named `what` (`forward 2200000x12`), after the work queued before it.
    pub fn start(client: &Client, what: impl FnOnce() -> String) -> Self {
        let client = std::env::var_os(STAGE_TIMES).is_some().then(|| client.clone());
        let what = client.as_ref().map(|_| what()).unwrap_or_default();
        let mut clock = Self { client, what, last: Instant::now(), stages: Vec::new() };
        clock.wait();
        clock.last = Instant::now();
        clock
    }

    /// Ends the stage named `stage`: waits for the device and records the time since the previous mark.
    pub fn mark(&mut self, stage: impl FnOnce() -> String) {
        if self.client.is_none() {
            return;
        }
        self.wait();
        let now = Instant::now();
        self.stages.push((stage(), (now - self.last).as_secs_f64() * 1e3));
        self.last = now;
    }

    fn wait(&self) {
        if let Some(client) = &self.client
            && let Err(error) = block_on(client.sync())
        {
            eprintln!("splat stage times: waiting for the device failed: {error:?}");
        }
    }
}

impl Drop for StageClock {
    /// Writes the call's line, once its stages are marked.
    fn drop(&mut self) {
        if self.client.is_none() || self.stages.is_empty() {
            return;
        }
        let total: f64 = self.stages.iter().map(|(_, ms)| ms).sum();
        let stages: Vec<String> = self.stages.iter().map(|(name, ms)| format!("{name} {ms:.2}")).collect();
        eprintln!("splat {}: {} (total {total:.2} ms)", self.what, stages.join(", "));
    }
}
