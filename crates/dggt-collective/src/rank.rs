//! A rank's number in its process group: the group ([`crate::group`]) hands it out and its errors
//! ([`crate::CollectiveError`]) name it, so it stands below both.

/// A rank's number in its group, from 0.
pub type Rank = usize;
