//! Time and cameras of one forward pass: which rig camera took each input view and when, the release's mapping
//! from frame index to scene time, and the camera of any target view interpolated from the inputs.
//!
//! Scene time follows the release: with inputs spanning log frames `first..=last` and `n` distinct input
//! frames, frame `f` is at `t = (f - first) / (last - first) · n / 4`. Targets outside the span extrapolate
//! linearly. Cameras are interpolated as poses (world-from-camera: camera centre linear, rotation SLERP,
//! intrinsics linear) between the two input views of the same rig camera that bracket the target time.

use dggt_geom::PosedCamera;
use serde::{Deserialize, Serialize};

use crate::error::SceneError;

/// One input view: the rig camera it came from, its scene time and the camera its Gaussians are placed with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputView {
    /// Position of the camera in the rig (the scene's camera list).
    pub rig_camera: usize,
    pub time: f64,
    pub camera: PosedCamera,
}

/// A view to render: which rig camera, when, and (once known) from where.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetView {
    pub rig_camera: usize,
    pub time: f64,
    pub camera: PosedCamera,
}

/// The release's frame-index-to-time mapping for one set of input frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timeline {
    first: f64,
    /// Time per frame index.
    rate: f64,
}

impl Timeline {
    /// The timeline of inputs taken at log frames `input_frames` (any order, repeats allowed).
    pub fn new(input_frames: &[usize]) -> Result<Self, SceneError> {
        let mut frames = input_frames.to_vec();
        frames.sort_unstable();
        frames.dedup();
        let (Some(&first), Some(&last)) = (frames.first(), frames.last()) else {
            return Err(SceneError::NoInputFrames);
        };
        let span = (last - first) as f64;
        let rate = if span > 0.0 { frames.len() as f64 / 4.0 / span } else { 0.0 };
        Ok(Self { first: first as f64, rate })
    }

    /// Log frames per unit of scene time (zero for a single input frame, whose timeline does not advance).
    pub fn frames_per_time(&self) -> f64 {
        if self.rate > 0.0 { 1.0 / self.rate } else { 0.0 }
    }

    /// Scene time of log frame `frame` (fractional frames allowed).
    pub fn time(&self, frame: f64) -> f64 {
        (frame - self.first) * self.rate
    }
}

/// The camera of `rig_camera` at `time`, interpolated between the input views of that camera that bracket it
/// (extrapolated from the nearest pair outside their span; the only view when there is one).
pub fn interpolate_camera(views: &[InputView], rig_camera: usize, time: f64) -> Result<PosedCamera, SceneError> {
    if !time.is_finite() {
        return Err(SceneError::NonFiniteTime { what: "target time", value: time });
    }
    let mut own: Vec<&InputView> = views.iter().filter(|v| v.rig_camera == rig_camera).collect();
    own.sort_by(|a, b| a.time.total_cmp(&b.time));
    own.dedup_by(|a, b| a.time == b.time);
    match own.as_slice() {
        [] => Err(SceneError::NoInputForCamera { camera: rig_camera }),
        [only] => Ok(only.camera),
        _ => {
            let after = own.iter().position(|v| v.time > time).unwrap_or(own.len() - 1).max(1);
            let (a, b) = (own[after - 1], own[after]);
            Ok(PosedCamera::interpolate(&a.camera, a.time, &b.camera, b.time, time)?)
        }
    }
}

/// Index (into `views`) of the input view of `rig_camera` nearest in time to `time`; the earlier on a tie.
pub fn nearest_view(views: &[InputView], rig_camera: usize, time: f64) -> Option<usize> {
    nearest_in_time(views.iter().map(|v| (v.rig_camera, v.time)), rig_camera, time)
}

/// Position among `candidates` (each a rig camera and a time, in any one unit) of the one of `rig_camera`
/// nearest in time to `time`; the earlier on a tie; `None` when no candidate shows that camera.
pub fn nearest_in_time(
    candidates: impl IntoIterator<Item = (usize, f64)>,
    rig_camera: usize,
    time: f64,
) -> Option<usize> {
    candidates
        .into_iter()
        .enumerate()
        .filter(|(_, (camera, _))| *camera == rig_camera)
        .min_by(|(_, (_, a)), (_, (_, b))| (a - time).abs().total_cmp(&(b - time).abs()).then(a.total_cmp(b)))
        .map(|(i, _)| i)
}

/// Which input views lend their dynamic Gaussians to a target time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DynamicBlend {
    /// The view of the target's rig camera nearest in time, at full opacity (the release's choice).
    #[default]
    Nearest,
    /// The two views of the target's rig camera that bracket its time, opacities scaled by linear weights in
    /// time (`(t1 - t) / (t1 - t0)` for the earlier one): a moving object fades from where the earlier view saw
    /// it to where the later one did, as the static union fades through the lifespans. A target at an input's
    /// time, or outside the inputs' span, takes the nearest view alone.
    CrossFade,
}

/// The input views (indices into `views`) whose dynamic Gaussians are drawn at `time` for `rig_camera`, each
/// with the weight its dynamic opacities are multiplied by; empty when the rig camera has no input view.
pub fn dynamic_sources(views: &[InputView], rig_camera: usize, time: f64, blend: DynamicBlend) -> Vec<(usize, f64)> {
    let Some(nearest) = nearest_view(views, rig_camera, time) else { return Vec::new() };
    if blend == DynamicBlend::Nearest || views[nearest].time == time {
        return vec![(nearest, 1.0)];
    }
    let of_camera = || views.iter().enumerate().filter(|(_, v)| v.rig_camera == rig_camera);
    let before = of_camera().filter(|(_, v)| v.time < time).max_by(|(_, a), (_, b)| a.time.total_cmp(&b.time));
    let after = of_camera().filter(|(_, v)| v.time > time).min_by(|(_, a), (_, b)| a.time.total_cmp(&b.time));
    match (before, after) {
        (Some((i0, v0)), Some((i1, v1))) => {
            let earlier = (v1.time - time) / (v1.time - v0.time);
            vec![(i0, earlier), (i1, 1.0 - earlier)]
        }
        _ => vec![(nearest, 1.0)],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dggt_geom::glam::{DQuat, DVec3};
    use dggt_geom::{PinholeIntrinsics, WorldFromCamera};

    fn camera(x: f64, yaw: f64) -> PosedCamera {
        PosedCamera {
            world_from_camera: WorldFromCamera::from_rotation_translation(
                DQuat::from_rotation_y(yaw),
                DVec3::new(x, 0.0, 0.0),
            )
            .unwrap(),
            intrinsics: PinholeIntrinsics::new(50.0, 50.0, 32.0, 24.0).unwrap(),
        }
    }

    fn view(rig_camera: usize, time: f64, x: f64) -> InputView {
        InputView { rig_camera, time, camera: camera(x, x * 0.1) }
    }

    #[test]
    fn times_follow_the_release() {
        // Consecutive frames 10..=13: t = i / 3 · 4 / 4.
        let timeline = Timeline::new(&[10, 11, 12, 13]).unwrap();
        let times: Vec<f64> = (10..14).map(|f| timeline.time(f as f64)).collect();
        let expected = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];
        assert!(times.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12), "{times:?}");
        // Sparse inputs: the span is still n / 4.
        let timeline = Timeline::new(&[0, 5, 10, 15, 20, 25, 30, 35]).unwrap();
        assert!((timeline.time(35.0) - 2.0).abs() < 1e-12 && (timeline.time(40.0) - 16.0 / 7.0 * 1.0).abs() < 1e-9);
        assert_eq!(Timeline::new(&[3]).unwrap().time(3.0), 0.0);
        assert!(Timeline::new(&[]).is_err());
    }

    #[test]
    fn cameras_interpolate_between_bracketing_inputs() {
        let views = [view(0, 0.0, 0.0), view(1, 0.0, 5.0), view(0, 1.0, 2.0), view(0, 2.0, 6.0)];
        let at = |t| interpolate_camera(&views, 0, t).unwrap().world_from_camera.translation().x;
        assert!((at(0.0) - 0.0).abs() < 1e-12 && (at(1.0) - 2.0).abs() < 1e-12);
        assert!((at(0.5) - 1.0).abs() < 1e-12 && (at(1.5) - 4.0).abs() < 1e-12);
        // Outside the span: extrapolated from the end pair.
        assert!((at(-0.5) + 1.0).abs() < 1e-12 && (at(2.5) - 8.0).abs() < 1e-12);
        // A camera seen once is held.
        let single = interpolate_camera(&views, 1, 3.0).unwrap();
        assert_eq!(single.world_from_camera.translation().x, 5.0);
        assert!(matches!(interpolate_camera(&views, 2, 0.0), Err(SceneError::NoInputForCamera { camera: 2 })));
        assert!(interpolate_camera(&views, 0, f64::NAN).is_err());
    }

    #[test]
    fn nearest_view_prefers_the_earlier_on_ties() {
        let views = [view(0, 0.0, 0.0), view(1, 0.4, 5.0), view(0, 1.0, 2.0)];
        assert_eq!(nearest_view(&views, 0, 0.5), Some(0));
        assert_eq!(nearest_view(&views, 0, 0.51), Some(2));
        assert_eq!(nearest_view(&views, 1, 9.0), Some(1));
        assert_eq!(nearest_view(&views, 3, 0.0), None);
    }

    #[test]
    fn cross_fades_weigh_the_bracketing_views_by_time() {
        let views = [view(0, 0.0, 0.0), view(1, 0.4, 5.0), view(0, 1.0, 2.0), view(0, 2.0, 3.0)];
        let fade = |camera, time| dynamic_sources(&views, camera, time, DynamicBlend::CrossFade);
        let weights = fade(0, 0.25);
        assert_eq!(weights.iter().map(|w| w.0).collect::<Vec<_>>(), [0, 2]);
        assert!((weights[0].1 - 0.75).abs() < 1e-12 && (weights[1].1 - 0.25).abs() < 1e-12, "{weights:?}");
        let weights = fade(0, 1.5);
        assert_eq!(weights.iter().map(|w| w.0).collect::<Vec<_>>(), [2, 3]);
        assert!((weights[0].1 - 0.5).abs() < 1e-12, "{weights:?}");
        // At an input's time, outside the span, or with one view of the camera: the nearest alone.
        assert_eq!(fade(0, 1.0), [(2, 1.0)]);
        assert_eq!(fade(0, -1.0), [(0, 1.0)]);
        assert_eq!(fade(0, 7.0), [(3, 1.0)]);
        assert_eq!(fade(1, 0.0), [(1, 1.0)]);
        assert!(fade(4, 0.0).is_empty());
        assert_eq!(dynamic_sources(&views, 0, 0.25, DynamicBlend::Nearest), [(0, 1.0)]);
    }
}
