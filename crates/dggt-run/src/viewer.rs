//! The `[viewer]` section of a run's configuration: what a run shown live (`dggt train --rerun`,
//! `dggt refine-train --rerun`) hands its viewer, and how often. A step's scalars are cheap; a validation
//! pass's pictures copy images (and, for DGGT, the window's Gaussians) to the host.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewerSection {
    /// Log a step's losses, learning rate and gradient norm every this many steps (at least 1).
    pub scalars_every: u64,
    /// Picture every this many validation passes (DGGT: renders beside the truth and their difference, depth
    /// and dynamic masks, the cameras, the Gaussians; the refiner: held-out renders before and after); 0 pictures
    /// none and logs the scores alone.
    pub snapshot_every: u64,
    /// At most this many of a DGGT validation window's Gaussians as splats (thinned evenly); 0 logs none.
    pub max_splats: usize,
    /// Held-out pairs a refiner's validation pass pictures.
    pub refiner_pairs: usize,
}

impl Default for ViewerSection {
    fn default() -> Self {
        Self { scalars_every: 1, snapshot_every: 1, max_splats: 100_000, refiner_pairs: 4 }
    }
}

impl ViewerSection {
    /// Why the section cannot be used, when it cannot: `scalars_every` of 0.
    pub fn check(&self) -> Result<(), String> {
        match self.scalars_every {
            0 => Err("viewer.scalars_every must be at least 1, got 0".into()),
            _ => Ok(()),
        }
    }

    /// Whether the validation pass that follows `passes_before` earlier ones is pictured.
    pub fn pictures_pass(&self, passes_before: u64) -> bool {
        self.snapshot_every > 0 && passes_before.is_multiple_of(self.snapshot_every)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalars_every_zero_is_refused_naming_it() {
        let section = ViewerSection { scalars_every: 0, ..ViewerSection::default() };
        assert!(section.check().unwrap_err().contains("viewer.scalars_every"));
        assert!(ViewerSection::default().check().is_ok());
    }

    #[test]
    fn every_nth_pass_is_pictured_and_none_at_zero() {
        let every = |n| ViewerSection { snapshot_every: n, ..ViewerSection::default() };
        let pictured = |section: ViewerSection| (0..6).filter(|&k| section.pictures_pass(k)).collect::<Vec<u64>>();
        assert_eq!(pictured(every(1)), [0, 1, 2, 3, 4, 5]);
        assert_eq!(pictured(every(3)), [0, 3]);
        assert_eq!(pictured(every(0)), Vec::<u64>::new());
    }
}
