//! Property tests of the public geometry API: pose-encoding round trips, SLERP's edge cases, camera
//! interpolation, depth unprojection against projection, rigid-transform algebra, and that invalid input is
//! an error rather than a panic or a silent NaN.
//!
//! Random rotations deliberately include half-turns (scalar part zero or nearly so), where the sign of a
//! quaternion and the matrix-to-quaternion conversion are most fragile.

use std::f64::consts::PI;

use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{
    Camera, CameraFromWorld, Ego, GeomError, ImageSize, PinholeIntrinsics, PixelConvention, PoseEncoding, PosedCamera,
    QuatWxyz, QuatXyzw, Rigid, WaymoCamera, World, WorldFromCamera, interpolate_rigid, slerp, unproject_depth_map,
};
use proptest::prelude::*;

const CASES: u32 = 256;

/// `|a - b| <= tolerance · max(1, |a|, |b|)`: relative for large values, absolute near zero.
fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance * a.abs().max(b.abs()).max(1.0)
}

/// Whether two unit quaternions agree componentwise, allowing `q` and `-q` (the same rotation).
fn same_rotation(a: DQuat, b: DQuat, tolerance: f64) -> bool {
    a.abs_diff_eq(b, tolerance) || a.abs_diff_eq(-b, tolerance)
}

/// The angle of the rotation taking `a` to `b`, accurate for small angles too.
fn rotation_angle(a: DQuat, b: DQuat) -> f64 {
    let b = if a.dot(b) < 0.0 { -b } else { b };
    2.0 * (a - b).length().atan2((a + b).length())
}

/// Largest difference between two transforms relative to the size of their translations.
fn rigid_error<To, From>(a: &Rigid<To, From>, b: &Rigid<To, From>) -> f64 {
    a.max_abs_difference(b) / a.translation().length().max(b.translation().length()).max(1.0)
}

fn unit_axis() -> impl Strategy<Value = DVec3> {
    prop::array::uniform3(-1.0..1.0f64)
        .prop_map(DVec3::from_array)
        .prop_filter("axis away from zero", |v| v.length() > 0.1)
        .prop_map(DVec3::normalize)
}

/// Rotations: generic ones, ones within a milliradian of a half-turn on either side, and exact half-turns
/// (scalar part exactly zero).
fn rotation() -> impl Strategy<Value = DQuat> {
    prop_oneof![
        3 => prop::array::uniform4(-1.0..1.0f64)
            .prop_map(DQuat::from_array)
            .prop_filter("quaternion away from zero", |q| q.length() > 0.1)
            .prop_map(DQuat::normalize),
        1 => (unit_axis(), -1e-3..1e-3f64).prop_map(|(axis, offset)| DQuat::from_axis_angle(axis, PI + offset)),
        1 => unit_axis().prop_map(|axis| DQuat::from_xyzw(axis.x, axis.y, axis.z, 0.0)),
    ]
}

fn translation() -> impl Strategy<Value = DVec3> {
    prop::array::uniform3(-1e3..1e3f64).prop_map(DVec3::from_array)
}

fn rigid<To: 'static, From: 'static>() -> impl Strategy<Value = Rigid<To, From>>
where
    Rigid<To, From>: std::fmt::Debug,
{
    (rotation(), translation()).prop_map(|(r, t)| Rigid::from_rotation_translation(r, t).unwrap())
}

fn image_size() -> impl Strategy<Value = ImageSize> {
    (1u32..4000, 1u32..4000).prop_map(|(w, h)| ImageSize::new(w, h).unwrap())
}

/// Pairs `(a, b)` for SLERP: generic, nearly identical (1e-12 to 1e-6 rad apart), antipodal (`b = -a`,
/// possibly perturbed), and exactly a half-turn apart (`a · b = 0`). Both are scaled away from unit norm.
fn slerp_pair() -> impl Strategy<Value = (DQuat, DQuat)> {
    let scale = || prop_oneof![Just(1.0), 1e-3..1e3f64];
    let pair = prop_oneof![
        (rotation(), rotation()),
        (rotation(), unit_axis(), -12.0..-6.0f64)
            .prop_map(|(a, axis, log_angle)| (a, a * DQuat::from_axis_angle(axis, 10f64.powf(log_angle)))),
        (rotation(), unit_axis(), prop_oneof![Just(0.0), 1e-9..1e-3f64])
            .prop_map(|(a, axis, angle)| (a, -(a * DQuat::from_axis_angle(axis, angle)))),
        (rotation(), unit_axis()).prop_map(|(a, axis)| (a, a * DQuat::from_xyzw(axis.x, axis.y, axis.z, 0.0))),
    ];
    (pair, scale(), scale()).prop_map(|((a, b), sa, sb)| (a * sa, b * sb))
}

fn is_zero_quaternion<T>(result: &Result<T, GeomError>) -> bool {
    matches!(result, Err(GeomError::ZeroQuaternion { .. }))
}

fn is_non_finite<T>(result: &Result<T, GeomError>) -> bool {
    matches!(result, Err(GeomError::NonFinite { .. }))
}

fn non_finite() -> impl Strategy<Value = f64> {
    prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn pose_encoding_round_trips(
        extrinsic in rigid::<Camera, World>(),
        fov_h in 0.2..2.5f64,
        fov_w in 0.2..2.5f64,
        size in image_size(),
    ) {
        let intrinsics = PinholeIntrinsics::from_fov(fov_h, fov_w, size).unwrap();
        let encoding = PoseEncoding::encode(&extrinsic, &intrinsics, size);
        prop_assert!(encoding.rotation.0[3] >= 0.0, "scalar part {}", encoding.rotation.0[3]);
        let (decoded_extrinsic, decoded_intrinsics) = encoding.decode(size).unwrap();
        prop_assert!(rigid_error(&decoded_extrinsic, &extrinsic) < 1e-9, "{decoded_extrinsic:?} vs {extrinsic:?}");
        for (got, want) in [
            (decoded_intrinsics.fx, intrinsics.fx),
            (decoded_intrinsics.fy, intrinsics.fy),
            (decoded_intrinsics.cx, intrinsics.cx),
            (decoded_intrinsics.cy, intrinsics.cy),
        ] {
            prop_assert!(close(got, want, 1e-9), "{decoded_intrinsics:?} vs {intrinsics:?}");
        }
        let array = encoding.to_array();
        prop_assert_eq!(PoseEncoding::from_array(array), encoding);
    }

    #[test]
    fn decoding_then_encoding_standardises_the_quaternion(
        translation in translation(),
        rotation in rotation(),
        norm in prop_oneof![Just(1.0), 1e-3..1e3f64],
        fov_h in 0.2..2.5f64,
        fov_w in 0.2..2.5f64,
        size in image_size(),
    ) {
        let raw = rotation * norm;
        let encoding = PoseEncoding {
            translation: translation.to_array(),
            rotation: QuatXyzw(raw.to_array()),
            fov_h,
            fov_w,
        };
        let (extrinsic, intrinsics) = encoding.decode(size).unwrap();
        let again = PoseEncoding::encode(&extrinsic, &intrinsics, size);
        let expected = QuatXyzw(raw.normalize().to_array()).standardized();
        let (got, want) = (DQuat::from_array(again.rotation.0), DQuat::from_array(expected.0));
        prop_assert!(again.rotation.0[3] >= 0.0);
        // With a scalar part at rounding level both signs are standardised; elsewhere the sign must match.
        let agrees = if want.w.abs() > 1e-9 { got.abs_diff_eq(want, 1e-12) } else { same_rotation(got, want, 1e-12) };
        prop_assert!(agrees, "{got:?} vs {want:?}");
        prop_assert_eq!(again.translation, encoding.translation);
        prop_assert!(close(again.fov_h, fov_h, 1e-12) && close(again.fov_w, fov_w, 1e-12));
    }

    #[test]
    fn slerp_hits_its_endpoints_and_stays_unit((a, b) in slerp_pair(), t in -0.5..1.5f64) {
        let (unit_a, unit_b) = (a.normalize(), b.normalize());
        let start = slerp(a, b, 0.0).unwrap();
        let end = slerp(a, b, 1.0).unwrap();
        prop_assert!(start.abs_diff_eq(unit_a, 1e-12), "{start:?} vs {unit_a:?}");
        prop_assert!(same_rotation(end, unit_b, 1e-12), "{end:?} vs {unit_b:?}");
        let q = slerp(a, b, t).unwrap();
        prop_assert!(q.is_finite() && (q.length() - 1.0).abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn slerp_moves_away_from_the_start_monotonically(
        (a, b) in slerp_pair(),
        mut ts in prop::collection::vec(0.0..=1.0f64, 2..16),
    ) {
        ts.sort_by(f64::total_cmp);
        let unit_a = a.normalize();
        let mut previous = 0.0;
        for t in ts {
            let angle = rotation_angle(unit_a, slerp(a, b, t).unwrap());
            prop_assert!(angle >= previous - 1e-12, "angle {angle} after {previous} at t = {t}");
            previous = angle;
        }
        prop_assert!(previous <= rotation_angle(unit_a, b.normalize()) + 1e-12);
    }

    #[test]
    fn slerp_matches_glam_on_generic_input(a in rotation(), b in rotation(), t in 0.0..=1.0f64) {
        prop_assume!(rotation_angle(a, b) > 1e-3);
        let ours = slerp(a, b, t).unwrap();
        let theirs = a.slerp(b, t);
        prop_assert!(same_rotation(ours, theirs, 1e-9), "{ours:?} vs {theirs:?}");
    }

    #[test]
    fn rigid_interpolation_is_exact_at_the_ends(
        a in rigid::<World, Ego>(),
        b in rigid::<World, Ego>(),
        t in -0.5..1.5f64,
    ) {
        prop_assert!(rigid_error(&interpolate_rigid(&a, &b, 0.0).unwrap(), &a) < 1e-12);
        prop_assert!(rigid_error(&interpolate_rigid(&a, &b, 1.0).unwrap(), &b) < 1e-12);
        let between = interpolate_rigid(&a, &b, t).unwrap();
        let centre = a.translation().lerp(b.translation(), t);
        prop_assert!(between.translation().abs_diff_eq(centre, 1e-12 * centre.length().max(1.0)));
    }

    #[test]
    fn camera_interpolation_moves_the_centre_linearly(
        pose_a in rigid::<World, Camera>(),
        pose_b in rigid::<World, Camera>(),
        time_a in -1e3..1e3f64,
        span in 1e-2..1e2f64,
        fraction in 0.0..=1.0f64,
    ) {
        let intrinsics_a = PinholeIntrinsics::new(500.0, 510.0, 320.0, 240.0).unwrap();
        let intrinsics_b = PinholeIntrinsics::new(700.0, 690.0, 300.0, 250.0).unwrap();
        let a = PosedCamera { world_from_camera: pose_a, intrinsics: intrinsics_a };
        let b = PosedCamera { world_from_camera: pose_b, intrinsics: intrinsics_b };
        let time_b = time_a + span;
        let at_a = PosedCamera::interpolate(&a, time_a, &b, time_b, time_a).unwrap();
        let at_b = PosedCamera::interpolate(&a, time_a, &b, time_b, time_b).unwrap();
        prop_assert!(rigid_error(&at_a.world_from_camera, &pose_a) < 1e-12);
        prop_assert!(rigid_error(&at_b.world_from_camera, &pose_b) < 1e-12);
        prop_assert!(close(at_a.intrinsics.fx, intrinsics_a.fx, 1e-12));
        prop_assert!(close(at_b.intrinsics.cy, intrinsics_b.cy, 1e-12));

        let time = time_a + fraction * span;
        let s = (time - time_a) / (time_b - time_a);
        let between = PosedCamera::interpolate(&a, time_a, &b, time_b, time).unwrap();
        let centre = pose_a.translation().lerp(pose_b.translation(), s);
        let got = between.world_from_camera.translation();
        prop_assert!(got.abs_diff_eq(centre, 1e-12 * centre.length().max(1.0)), "{got:?} vs {centre:?}");
    }

    #[test]
    fn unprojected_depth_projects_back_to_its_pixel(
        camera_from_world in rigid::<Camera, World>(),
        (width, height) in (1u32..8, 1u32..8),
        focal in (50.0..2000.0f64, 50.0..2000.0f64),
        principal in (-0.5..1.5f64, -0.5..1.5f64),
        depths in prop::collection::vec(0.1..1e3f32, 64),
    ) {
        let size = ImageSize::new(width, height).unwrap();
        let intrinsics =
            PinholeIntrinsics::new(focal.0, focal.1, principal.0 * width as f64, principal.1 * height as f64).unwrap();
        let depth = &depths[..size.area()];
        for convention in [PixelConvention::Centred, PixelConvention::Integer] {
            let points = unproject_depth_map(depth, size, &intrinsics, &camera_from_world, convention).unwrap();
            prop_assert_eq!(points.len(), depth.len());
            for (i, (point, &d)) in points.iter().zip(depth).enumerate() {
                let in_camera = camera_from_world.transform_point(*point);
                prop_assert!(close(in_camera.z, d as f64, 1e-9), "depth {} vs {d}", in_camera.z);
                let pixel = intrinsics.project(in_camera).unwrap();
                let expected = convention.coordinates(i as u32 % width, i as u32 / width);
                prop_assert!(pixel.abs_diff_eq(expected, 1e-6), "{convention:?}: {pixel:?} vs {expected:?}");
            }
        }
    }

    #[test]
    fn rigid_composition_is_associative_and_invertible(
        a in rigid::<World, Ego>(),
        b in rigid::<Ego, Camera>(),
        c in rigid::<Camera, WaymoCamera>(),
        point in translation(),
    ) {
        let scale = 1.0 + a.translation().length() + b.translation().length() + c.translation().length();
        let left = (a * b) * c;
        let right = a * (b * c);
        prop_assert!(left.max_abs_difference(&right) < 1e-12 * scale);
        prop_assert!((a * a.inverse()).max_abs_difference(&Rigid::IDENTITY) < 1e-12 * scale);
        prop_assert!((a.inverse() * a).max_abs_difference(&Rigid::IDENTITY) < 1e-12 * scale);
        prop_assert!(a.inverse().inverse().max_abs_difference(&a) < 1e-12 * scale);
        let mapped = left.transform_point(point);
        let chained = a.transform_point(b.transform_point(c.transform_point(point)));
        prop_assert!(mapped.abs_diff_eq(chained, 1e-12 * (scale + point.length())));
        let back = left.inverse().transform_point(mapped);
        prop_assert!(back.abs_diff_eq(point, 1e-12 * (scale + point.length())));
    }

    #[test]
    fn rows_round_trip(x in rigid::<World, Camera>()) {
        let back = WorldFromCamera::from_rows(x.to_rows()).unwrap();
        prop_assert!(rigid_error(&back, &x) < 1e-12, "{back:?} vs {x:?}");
        let rows = x.to_rows();
        let back_3x4 = WorldFromCamera::from_rows_3x4([rows[0], rows[1], rows[2]]).unwrap();
        prop_assert!(rigid_error(&back_3x4, &x) < 1e-12);
    }

    #[test]
    fn zero_quaternions_are_errors(
        translation in translation(),
        size in image_size(),
        other in rotation(),
        t in -0.5..1.5f64,
    ) {
        let encoding =
            PoseEncoding { translation: translation.to_array(), rotation: QuatXyzw([0.0; 4]), fov_h: 1.0, fov_w: 1.0 };
        let zero = DQuat::from_array([0.0; 4]);
        prop_assert!(is_zero_quaternion(&encoding.decode(size)));
        prop_assert!(is_zero_quaternion(&QuatWxyz([0.0; 4]).to_rotation()));
        prop_assert!(is_zero_quaternion(&slerp(zero, other, t)));
        prop_assert!(is_zero_quaternion(&slerp(other, zero, t)));
        prop_assert!(is_zero_quaternion(&CameraFromWorld::from_rotation_translation(zero, translation)));
    }

    #[test]
    fn non_finite_values_are_errors(
        base in rigid::<World, Camera>(),
        other in rotation(),
        size in image_size(),
        bad in non_finite(),
        position in 0usize..16,
    ) {
        let intrinsics = PinholeIntrinsics::new(500.0, 500.0, 320.0, 240.0).unwrap();
        let mut encoding = PoseEncoding::encode(&base.inverse(), &intrinsics, size).to_array();
        encoding[position % 9] = bad;
        prop_assert!(is_non_finite(&PoseEncoding::from_array(encoding).decode(size)));

        let mut rows = base.to_rows();
        rows[position / 4][position % 4] = bad;
        prop_assert!(is_non_finite(&WorldFromCamera::from_rows(rows)));

        let mut q = base.rotation().to_array();
        q[position % 4] = bad;
        prop_assert!(is_non_finite(&slerp(DQuat::from_array(q), other, 0.5)));
        prop_assert!(is_non_finite(&slerp(other, DQuat::from_array(q), 0.5)));
        prop_assert!(is_non_finite(&slerp(other, base.rotation(), bad)));
        prop_assert!(is_non_finite(&QuatXyzw(q).to_rotation()));
        prop_assert!(is_non_finite(&WorldFromCamera::from_rotation_translation(DQuat::from_array(q), DVec3::ZERO)));
        prop_assert!(is_non_finite(&interpolate_rigid(&base, &base, bad)));

        let mut k = [500.0, 500.0, 320.0, 240.0];
        k[position % 4] = bad;
        prop_assert!(is_non_finite(&PinholeIntrinsics::new(k[0], k[1], k[2], k[3])));
        let invalid = PinholeIntrinsics { fx: k[0], fy: k[1], cx: k[2], cy: k[3] };
        let one_pixel = ImageSize::new(1, 1).unwrap();
        let unprojected = unproject_depth_map(&[1.0], one_pixel, &invalid, &base.inverse(), PixelConvention::Integer);
        prop_assert!(is_non_finite(&unprojected));

        let camera = PosedCamera { world_from_camera: base, intrinsics };
        prop_assert!(is_non_finite(&PosedCamera::interpolate(&camera, 0.0, &camera, 1.0, bad)));
        prop_assert!(is_non_finite(&PosedCamera::interpolate(&camera, bad, &camera, 1.0, 0.5)));
    }
}
