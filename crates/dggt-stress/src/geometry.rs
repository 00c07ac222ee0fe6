//! Stress cases of the host geometry that every render goes through: camera interpolation (SLERP between
//! near-identical and opposite rotations, huge translations, extrapolation), the frame-to-time mapping, and
//! the decoding of extreme pose encodings.
//!
//! Poses are world-from-camera (OpenCV axes), rotations unit quaternions; a case passes when every
//! interpolated camera is finite with a unit rotation and positive focal lengths, or the input is rejected with
//! an error.

use dggt_geom::{ImageSize, PinholeIntrinsics, PoseEncoding, PosedCamera, WorldFromCamera};
use dggt_scene::{InputView, Timeline, interpolate_camera};
use glam::{DQuat, DVec3};

use crate::error::StressError;
use crate::probe::{Probe, Stage};

/// Times at which the cases interpolate between inputs at times 0 and 1 (outside: extrapolated).
const TIMES: [f64; 7] = [-1.0, 0.0, 1e-12, 0.25, 0.5, 1.0, 3.0];

fn camera(rotation: DQuat, translation: DVec3) -> Result<PosedCamera, StressError> {
    let world_from_camera = WorldFromCamera::from_rotation_translation(rotation, translation)?;
    let intrinsics = PinholeIntrinsics::new(60.0, 60.0, 35.0, 28.0)?;
    Ok(PosedCamera { world_from_camera, intrinsics })
}

/// Checks one camera: finite, unit rotation, positive focal lengths.
pub(crate) fn check_camera(probe: &mut Probe, what: &str, camera: &PosedCamera) {
    let rows = camera.world_from_camera.to_rows();
    probe.values(Stage::Geometry, &format!("{what} world_from_camera"), rows.iter().flatten().copied());
    let k = camera.intrinsics;
    probe.values(Stage::Geometry, &format!("{what} intrinsics"), [k.fx, k.fy, k.cx, k.cy]);
    let norm = camera.world_from_camera.rotation().length();
    probe.require(Stage::Geometry, &format!("{what} rotation"), (norm - 1.0).abs() < 1e-9, format!("norm {norm}"));
    probe.require(Stage::Geometry, &format!("{what} focal"), k.fx > 0.0 && k.fy > 0.0, "non-positive focal length");
}

/// Interpolates between two cameras of one rig camera at inputs times 0 and 1, at every time of [`TIMES`].
fn interpolate_pair(probe: &mut Probe, a: PosedCamera, b: PosedCamera) -> Result<(), StressError> {
    let views = [InputView { rig_camera: 0, time: 0.0, camera: a }, InputView { rig_camera: 0, time: 1.0, camera: b }];
    for time in TIMES {
        let camera = interpolate_camera(&views, 0, time)?;
        check_camera(probe, &format!("camera at t={time}"), &camera);
    }
    Ok(())
}

/// Rotations 1e-12 rad apart: SLERP's angle is at the edge of its small-angle branch.
pub fn near_identical_rotations(probe: &mut Probe) -> Result<(), StressError> {
    let a = camera(DQuat::IDENTITY, DVec3::ZERO)?;
    let b = camera(DQuat::from_rotation_y(1e-12), DVec3::new(0.0, 0.0, 1.5))?;
    interpolate_pair(probe, a, b)?;
    let c = camera(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 1.5))?;
    interpolate_pair(probe, a, c)
}

/// Rotations half a turn apart, and a rotation against its own negated quaternion (the same rotation).
pub fn opposite_rotations(probe: &mut Probe) -> Result<(), StressError> {
    let a = camera(DQuat::IDENTITY, DVec3::ZERO)?;
    let b = camera(DQuat::from_rotation_y(std::f64::consts::PI), DVec3::X)?;
    interpolate_pair(probe, a, b)?;
    let q = DQuat::from_rotation_z(0.3);
    let c = camera(q, DVec3::ZERO)?;
    let d = camera(-q, DVec3::Y)?;
    interpolate_pair(probe, c, d)?;
    let slightly_less = camera(DQuat::from_rotation_x(std::f64::consts::PI - 1e-9), DVec3::ZERO)?;
    interpolate_pair(probe, a, slightly_less)
}

/// Camera centres at 1e6 and 1e15 (metres, or the network's units).
pub fn huge_translations(probe: &mut Probe) -> Result<(), StressError> {
    for scale in [1e6, 1e15] {
        let a = camera(DQuat::IDENTITY, DVec3::splat(scale))?;
        let b = camera(DQuat::from_rotation_y(0.1), DVec3::splat(-scale))?;
        interpolate_pair(probe, a, b)?;
    }
    Ok(())
}

/// The release's frame-to-time mapping for one frame, repeated frames and huge frame indices.
pub fn timelines(probe: &mut Probe) -> Result<(), StressError> {
    let cases: [&[usize]; 4] = [&[7], &[3, 3, 3], &[0, 1_000_000_000], &[usize::MAX / 2, usize::MAX / 2 + 8]];
    for frames in cases {
        let timeline = Timeline::new(frames)?;
        let first = frames[0] as f64;
        let times = [first - 1.0, first, first + 0.5, first + 8.0].map(|f| timeline.time(f));
        probe.values(Stage::Geometry, &format!("timeline {frames:?}"), times);
    }
    Ok(())
}

/// Extreme camera-head encodings: tiny and huge quaternions and translations, fields of view at their limits.
/// A zero quaternion must be an error; everything else must decode to a valid camera.
pub fn extreme_pose_encodings(probe: &mut Probe) -> Result<(), StressError> {
    let size = ImageSize::new(70, 56)?;
    let encodings: [[f64; 9]; 5] = [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1e-20, 1.0, 1.2],
        [1e9, -1e9, 1e9, 0.0, 0.0, 0.0, 1e20, 1.0, 1.2],
        [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.05, 0.05],
        [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 3.0, 3.0],
        [0.0, 0.0, 0.0, -1e-30, 0.0, 0.0, 0.0, 1.0, 1.2],
    ];
    for (i, values) in encodings.iter().enumerate() {
        match PoseEncoding::from_array(*values).decode(size) {
            Ok((camera_from_world, intrinsics)) => {
                let camera = PosedCamera { world_from_camera: camera_from_world.inverse(), intrinsics };
                check_camera(probe, &format!("encoding {i}"), &camera);
            }
            Err(error) => probe.require(
                Stage::Geometry,
                &format!("encoding {i}"),
                values[3..7].iter().map(|v| v * v).sum::<f64>() < 1e-40,
                format!("rejected a valid encoding: {error}"),
            ),
        }
    }
    let zero = PoseEncoding::from_array([0.0; 9]).decode(size);
    probe.require(Stage::Geometry, "zero encoding", zero.is_err(), "a zero quaternion decoded without an error");
    Ok(())
}
