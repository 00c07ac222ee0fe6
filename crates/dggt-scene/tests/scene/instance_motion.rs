//! Dynamic Gaussians moved along their object's trajectory: a patch of dynamic pixels that slides across three
//! input views is one instance; at an input's own time assembly returns that input's Gaussians exactly, between
//! inputs the instance's rows move rigidly (means and rotations) and the other rows are held.

use burn::tensor::{Device, Tensor};
use dggt_geom::glam::{DQuat, DVec3};
use dggt_instances::InstanceSettings;
use dggt_scene::{
    AssemblySettings, DynamicMotion, PixelGaussians, TargetView, assemble, assembled_velocities, interpolate_camera,
    render_flow,
};

use crate::common::{H, S, W, in_patch, pixels};

fn host(tensor: Tensor<2>) -> Vec<f32> {
    tensor.into_data().try_into_vec::<f32>().unwrap()
}

fn target(pixels: &PixelGaussians, time: f64) -> TargetView {
    TargetView { rig_camera: 0, time, camera: interpolate_camera(&pixels.views, 0, time).unwrap() }
}

#[test]
fn the_patch_is_one_instance_through_every_view() {
    let settings = InstanceSettings::default();
    let pixels = pixels(&Device::flex()).with_instances(&settings).unwrap();
    let instances = pixels.instances().expect("instances were found");
    assert_eq!(instances.len(), 1, "{:?}", instances.instances);
    assert_eq!(instances.instances[0].appearances.len(), S);
    for view in 0..S {
        for pixel in 0..H * W {
            let expected = in_patch(view, pixel % W, pixel / W).then_some(0);
            assert_eq!(instances.instance_of(view, pixel), expected, "view {view}, pixel {pixel}");
        }
    }
    // The patch slides by 2 pixels at depth 4 (0.4) plus the camera's 0.3 per view: 0.7 along x.
    let step = instances.motion(0, 0.0, 0.5);
    assert!(step.translation.abs_diff_eq(DVec3::new(0.7, 0.0, 0.0), 1e-4), "{step:?}");
}

#[test]
fn at_an_input_time_nothing_moves_and_between_inputs_the_instance_moves_rigidly() {
    let device = Device::flex();
    let held = pixels(&device);
    let moving = held.clone().with_instances(&InstanceSettings::default()).unwrap();
    let velocity = AssemblySettings::exact();
    let rigid = AssemblySettings { dynamic_motion: DynamicMotion::Instances, ..AssemblySettings::exact() };
    // At view 1's own time: the same tensors as without instances, bit for bit.
    let at_input = target(&held, 0.5);
    let a = assemble(&held, &at_input, &velocity).unwrap().gaussians;
    let b = assemble(&moving, &at_input, &rigid).unwrap().gaussians;
    assert!(host(a.means) == host(b.means), "the means moved at an input's own time");
    assert!(host(a.quats_wxyz) == host(b.quats_wxyz), "the rotations turned at an input's own time");

    // A quarter of the way from view 0 to view 1 (view 0 nearest): its patch rows come first among its
    // dynamic rows, moved by the instance's motion; the rest stay.
    let between = target(&held, 0.125);
    let assembled = assemble(&moving, &between, &rigid).unwrap().gaussians;
    let (means, quats) = (host(assembled.means), host(assembled.quats_wxyz));
    let (original_means, original_quats) = (host(held.means.clone()), host(held.quats_wxyz));
    let motion = moving.instances().unwrap().motion(0, 0.0, 0.125);
    assert!(motion.translation.length() > 0.1, "the patch moves: {motion:?}");
    let patch: Vec<usize> = (0..H * W).filter(|&p| in_patch(0, p % W, p / W)).collect();
    let others: Vec<usize> = (0..H * W).filter(|&p| !in_patch(0, p % W, p / W)).collect();
    let statics = S * H * W;
    for (slot, &pixel) in patch.iter().chain(&others).enumerate() {
        let row = statics + slot;
        let got = DVec3::new(means[row * 3] as f64, means[row * 3 + 1] as f64, means[row * 3 + 2] as f64);
        let was = DVec3::from_array(std::array::from_fn(|k| original_means[pixel * 3 + k] as f64));
        let expected = if slot < patch.len() { motion.apply(was) } else { was };
        assert!(got.abs_diff_eq(expected, 1e-5), "pixel {pixel}: {got} vs {expected}");
        let q = DQuat::from_xyzw(
            original_quats[pixel * 4 + 1] as f64,
            original_quats[pixel * 4 + 2] as f64,
            original_quats[pixel * 4 + 3] as f64,
            original_quats[pixel * 4] as f64,
        );
        let expected = if slot < patch.len() { motion.rotation * q } else { q };
        let got = &quats[row * 4..row * 4 + 4];
        let expected = [expected.w, expected.x, expected.y, expected.z];
        assert!(got.iter().zip(expected).all(|(g, e)| (*g as f64 - e).abs() < 1e-5), "pixel {pixel}: {got:?}");
    }
}

#[test]
fn the_flow_of_any_view_is_the_moving_objects_velocity() {
    let moving = pixels(&Device::flex()).with_instances(&InstanceSettings::default()).unwrap();
    let rigid = AssemblySettings { dynamic_motion: DynamicMotion::Instances, ..AssemblySettings::exact() };
    let between = target(&moving, 0.125);
    // Per assembled Gaussian: the static union's are still, view 0's patch rows move with the instance's step
    // (0.7 along x per half unit of scene time), the rest of view 0's dynamic rows are held.
    let velocities = assembled_velocities(&moving, &between, &rigid).unwrap();
    let statics = S * H * W;
    assert_eq!(velocities.len(), statics + H * W);
    assert!(velocities[..statics].iter().all(|v| *v == [0.0; 3]));
    let patch = (0..H * W).filter(|&p| in_patch(0, p % W, p / W)).count();
    for v in &velocities[statics..statics + patch] {
        assert!((v[0] - 1.4).abs() < 1e-3 && v[1].abs() < 1e-3 && v[2].abs() < 1e-3, "{v:?}");
    }
    assert!(velocities[statics + patch..].iter().all(|v| *v == [0.0; 3]));
    // Rendered: the moved patch's pixels see its velocity, the background none.
    let flow: Vec<f32> = render_flow(&moving, &between, &rigid).unwrap().into_data().try_into_vec().unwrap();
    let at = |column: usize, row: usize| &flow[(row * W + column) * 3..(row * W + column) * 3 + 3];
    let centre = at(9, 6);
    assert!(centre[0] > 1.0 && centre[0] < 1.45 && centre[1].abs() < 0.05, "{centre:?}");
    let background = at(20, 13);
    assert!(background.iter().all(|v| v.abs() < 1e-3), "{background:?}");
}
