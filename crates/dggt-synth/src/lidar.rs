//! A spinning lidar on the ego vehicle, ray-cast against the scene: the `lidar/{t}.bin` sweeps of the export.
//!
//! The sensor sits [`LIDAR_HEIGHT_M`] above the ego origin with the ego's axes (forward-left-up). It fires
//! [`BEAMS`] beams spread evenly in inclination over [`INCLINATION_RANGE_DEG`], at every [`AZIMUTH_STEP_DEG`] of
//! azimuth, all at the frame's instant (no rolling scan). A return is the nearest surface within [`MAX_RANGE_M`];
//! sky rays give none. Points, origins and flow are in the ego frame of that frame; flow is the hit surface's
//! velocity in m/s.

use dggt_data::lidar::LidarPoint;
use dggt_geom::glam::DVec3;

use crate::config::SynthConfig;
use crate::error::{Result, SynthError};
use crate::scene::SynthScene;

/// Height of the sensor above the ego origin (m).
pub const LIDAR_HEIGHT_M: f64 = 1.8;
/// Number of beams.
pub const BEAMS: usize = 32;
/// Lowest and highest beam inclination (degrees above the horizon).
pub const INCLINATION_RANGE_DEG: (f64, f64) = (-25.0, 5.0);
/// Azimuth between consecutive firings (degrees).
pub const AZIMUTH_STEP_DEG: f64 = 1.0;
/// Returns farther than this are dropped (m).
pub const MAX_RANGE_M: f64 = 80.0;

/// Unit ray directions of one sweep in the sensor (ego) axes, beam-major.
fn beam_directions() -> Vec<DVec3> {
    let (low, high) = INCLINATION_RANGE_DEG;
    let azimuths = (360.0 / AZIMUTH_STEP_DEG).round() as usize;
    (0..BEAMS)
        .flat_map(|beam| {
            let inclination = (low + (high - low) * beam as f64 / (BEAMS - 1) as f64).to_radians();
            (0..azimuths).map(move |a| {
                let azimuth = (a as f64 * AZIMUTH_STEP_DEG).to_radians();
                DVec3::new(azimuth.cos() * inclination.cos(), azimuth.sin() * inclination.cos(), inclination.sin())
            })
        })
        .collect()
}

/// The sweep of `frame`, in the ego frame of that frame.
pub fn sweep(scene: &SynthScene, frame: usize) -> Result<Vec<LidarPoint>> {
    let frames = scene.config().frames;
    let world_from_ego = scene.world_from_ego(frame).ok_or(SynthError::NoSuchFrame { frame, frames })?;
    let ego_from_world = world_from_ego.inverse();
    let at = scene.at(SynthConfig::frame_time(frame)).expect("frame times are finite");
    let origin = DVec3::new(0.0, 0.0, LIDAR_HEIGHT_M);
    let world_origin = world_from_ego.transform_point(origin);
    let points = beam_directions()
        .into_iter()
        .filter_map(|direction| {
            let hit = at.cast(world_origin, world_from_ego.transform_vector(direction))?;
            (hit.distance <= MAX_RANGE_M).then(|| LidarPoint {
                origin,
                point: ego_from_world.transform_point(hit.point),
                flow: ego_from_world.transform_vector(hit.velocity),
            })
        })
        .collect();
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lowest_beams_hit_the_road_at_the_distance_their_angle_gives() {
        let config = SynthConfig { seed: 3, frames: 2, cameras: 1, width: 32, height: 24 };
        let scene = crate::generate(&config).unwrap();
        let points = sweep(&scene, 1).unwrap();
        assert!(points.len() > BEAMS * 100, "most rays hit something: {}", points.len());
        // The first beam straight ahead meets the flat road (z = 0 in the ego frame) at h / tan(25 deg).
        let ahead = points.iter().find(|p| p.point.y.abs() < 1e-9 && p.point.x > 0.0).unwrap();
        let expected = LIDAR_HEIGHT_M / 25f64.to_radians().tan();
        assert!((ahead.point.x - expected).abs() < 1e-6 && ahead.point.z.abs() < 1e-6, "{:?}", ahead.point);
        assert!(points.iter().all(|p| (p.point - p.origin).length() <= MAX_RANGE_M + 1e-9));
    }
}
