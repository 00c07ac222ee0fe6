//! The stages of an evaluation that are timed, and the stopwatch that adds up their seconds: per scene, and
//! over the whole run for the report.

use std::time::Instant;

use crate::report::StageTime;

/// The stages timed, in order.
const STAGES: [&str; 5] = ["load", "forward", "assembly", "render", "metrics"];

pub(super) const LOAD: usize = 0;
pub(super) const FORWARD: usize = 1;
pub(super) const ASSEMBLY: usize = 2;
pub(super) const RENDER: usize = 3;
pub(super) const METRICS: usize = 4;

/// Seconds per stage.
#[derive(Debug, Clone, Default)]
pub(super) struct Stopwatch {
    seconds: [f64; STAGES.len()],
}

impl Stopwatch {
    pub(super) fn add(&mut self, stage: usize, since: Instant) {
        self.seconds[stage] += since.elapsed().as_secs_f64();
    }

    /// Adds the seconds of `times` (a scene's [`Stopwatch::list`]) stage by stage.
    pub(super) fn add_times(&mut self, times: &[StageTime]) {
        for stage in times {
            if let Some(i) = STAGES.iter().position(|s| *s == stage.stage) {
                self.seconds[i] += stage.seconds;
            }
        }
    }

    pub(super) fn list(&self) -> Vec<StageTime> {
        STAGES
            .iter()
            .zip(self.seconds)
            .map(|(stage, seconds)| StageTime { stage: stage.to_string(), seconds })
            .collect()
    }
}
