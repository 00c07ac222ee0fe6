//! A scene saved to one file and read back renders as before, a scene with a value that is not finite is not
//! written, and a file that does not hold a consistent scene is an error naming the file and what is wrong; an instance's placement moves its rows at every time.

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::glam::{DQuat, DVec3};
use dggt_instances::{InstanceSettings, Placement};
use dggt_model::sky::SkyGaussians;
use dggt_scene::{
    AssemblySettings, DynamicBlend, DynamicMotion, Scene4d, TargetView, interpolate_camera, load_scene, save_scene,
};

use crate::common::{H, S, W, in_patch, pixels};

fn host<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor.into_data().try_into_vec::<f32>().unwrap()
}

/// Four sky Gaussians far in front of the cameras.
fn sky(device: &Device) -> SkyGaussians {
    let tensor = |values: Vec<f32>, columns: usize| {
        Tensor::<2>::from_data(TensorData::new(values.clone(), [values.len() / columns, columns]), device)
    };
    SkyGaussians {
        visible_index: (0..4).collect(),
        rgb_mean: Tensor::zeros([4, 3], device),
        field_out: Tensor::zeros([4, 6], device),
        colors: tensor(vec![0.2, 0.4, 0.9, 0.3, 0.5, 0.8, 0.1, 0.3, 0.7, 0.4, 0.6, 1.0], 3),
        means: tensor(vec![-5.0, -3.0, 50.0, 5.0, -3.0, 50.0, -5.0, 3.0, 50.0, 5.0, 3.0, 50.0], 3),
        scales: tensor(vec![4.0; 12], 3),
        quats: tensor([1.0, 0.0, 0.0, 0.0].repeat(4), 4),
        opacities: Tensor::from_data(TensorData::new(vec![0.9f32; 4], [4]), device),
    }
}

fn scene(device: &Device) -> Scene4d {
    let pixels = pixels(device).with_instances(&InstanceSettings::default()).unwrap();
    let assembly = AssemblySettings {
        dynamic_motion: DynamicMotion::Instances,
        dynamic_blend: DynamicBlend::CrossFade,
        eps2d: 0.2,
        ..AssemblySettings::default()
    };
    Scene4d { pixels, sky: Some(sky(device)), assembly }
}

fn target(scene: &Scene4d, time: f64) -> TargetView {
    TargetView { rig_camera: 0, time, camera: interpolate_camera(scene.views(), 0, time).unwrap() }
}

fn saved(scene: &Scene4d, dir: &Path) -> std::path::PathBuf {
    let path = dir.join("scene.safetensors");
    save_scene(scene, &path).unwrap();
    path
}

#[test]
fn a_saved_scene_renders_as_before_at_and_between_the_inputs() {
    let device = Device::flex();
    let original = scene(&device);
    let dir = tempfile::tempdir().unwrap();
    let loaded = load_scene(&saved(&original, dir.path()), &device).unwrap();
    assert_eq!(loaded.pixels.instances(), original.pixels.instances());
    assert_eq!(loaded.assembly, original.assembly);
    assert_eq!(loaded.views(), original.views());
    for time in [0.0, 0.2, 0.5, 0.8] {
        let (a, b) =
            (original.render(&target(&original, time)).unwrap(), loaded.render(&target(&loaded, time)).unwrap());
        assert!(host(a.rgb) == host(b.rgb), "the colours differ at time {time}");
        assert!(host(a.alpha) == host(b.alpha), "the opacities differ at time {time}");
    }
}

#[test]
fn a_placement_moves_the_instance_at_every_time() {
    let device = Device::flex();
    let scene = scene(&device);
    let mut instances = scene.pixels.instances().unwrap().clone();
    let placement = Placement { turn: DQuat::from_rotation_y(0.2), offset: DVec3::new(0.5, 0.0, 1.0) };
    instances.instances[0].placement = placement;
    let shift = placement.at(instances.instances[0].trajectory.centre(0.5));
    let placed = scene.pixels.clone().with_known_instances(std::sync::Arc::new(instances)).unwrap();
    let settings = AssemblySettings { dynamic_motion: DynamicMotion::Instances, ..AssemblySettings::exact() };
    // At view 1's time its own rows are drawn: the patch's moved by the placement alone, the others held.
    let at_input = target(&scene, 0.5);
    let means = host(dggt_scene::assemble(&placed, &at_input, &settings).unwrap().gaussians.means);
    let original = host(scene.pixels.means);
    let statics = S * H * W;
    let patch: Vec<usize> = (0..H * W).filter(|&p| in_patch(1, p % W, p / W)).collect();
    let others: Vec<usize> = (0..H * W).filter(|&p| !in_patch(1, p % W, p / W)).collect();
    for (slot, &pixel) in patch.iter().chain(&others).enumerate() {
        let row = H * W + pixel;
        let was = DVec3::from_array(std::array::from_fn(|k| original[row * 3 + k] as f64));
        let got = DVec3::from_array(std::array::from_fn(|k| means[(statics + slot) * 3 + k] as f64));
        let expected = if slot < patch.len() { shift.apply(was) } else { was };
        assert!(got.abs_diff_eq(expected, 1e-5), "pixel {pixel}: {got} vs {expected}");
    }
}

fn load_error(path: &Path) -> String {
    load_scene(path, &Device::flex()).expect_err("the file is refused").to_string()
}

#[test]
fn a_file_that_is_not_a_consistent_scene_is_refused_by_name() {
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    let not_a_scene = dir.path().join("other.safetensors");
    std::fs::write(&not_a_scene, b"not a safetensors file").unwrap();
    let message = load_error(&not_a_scene);
    assert!(message.contains("other.safetensors") && message.contains("not a safetensors file"), "{message}");

    // A NaN among the means: the saver refuses it, and a file holding one (edited after saving) is refused.
    let mut broken = scene(&device);
    let mut means = host(broken.pixels.means.clone());
    means[3 * 7 + 1] = f32::NAN;
    broken.pixels.means = Tensor::from_data(TensorData::new(means, [S * H * W, 3]), &device);
    let message = save_scene(&broken, &dir.path().join("refused.safetensors")).unwrap_err().to_string();
    assert!(message.contains("pixels.means") && message.contains("row 7"), "{message}");
    assert!(!dir.path().join("refused.safetensors").exists(), "nothing is written for a refused scene");
    let path = saved(&scene(&device), dir.path());
    overwrite_f32(&path, "pixels.means", 3 * 7 + 1, f32::NAN);
    let message = load_error(&path);
    assert!(message.contains("pixels.means") && message.contains("row 7"), "{message}");

    // Scales of another width.
    let mut other_layout = scene(&device);
    other_layout.pixels.scales = Tensor::zeros([S * H * W, 4], &device);
    let message = load_error(&saved(&other_layout, dir.path()));
    assert!(message.contains("pixels.scales") && message.contains(&format!("{:?}", [S * H * W, 3])), "{message}");

    // A placement that is not finite is refused when saving; one that is not a rotation when loading.
    let mut non_finite = scene(&device);
    let mut instances = non_finite.pixels.instances().unwrap().clone();
    instances.instances[0].placement.offset.x = f64::INFINITY;
    non_finite.pixels = non_finite.pixels.with_known_instances(std::sync::Arc::new(instances)).unwrap();
    let message = save_scene(&non_finite, &dir.path().join("refused.safetensors")).unwrap_err().to_string();
    assert!(message.contains("instance 0") && message.contains("not finite"), "{message}");
    assert!(!dir.path().join("refused.safetensors").exists(), "nothing is written for a refused scene");
    let path = saved(&scene(&device), dir.path());
    rewrite_record(&path, |record| {
        record
            .replace("\"placement\":{\"turn_wxyz\":[1.0,0.0,0.0,0.0]", "\"placement\":{\"turn_wxyz\":[0.0,0.0,0.0,0.0]")
    });
    let message = load_error(&path);
    assert!(message.contains("instance 0") && message.contains("placement"), "{message}");
}

/// Sets element `index` of the f32 tensor `name` of the safetensors file `path` to `value`, in place.
fn overwrite_f32(path: &Path, name: &str, index: usize, value: f32) {
    let mut bytes = std::fs::read(path).unwrap();
    let header = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let tensors = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let start = tensors.tensor(name).unwrap().data().as_ptr() as usize - bytes.as_ptr() as usize;
    assert!(start >= 8 + header, "the tensor's data lies after the header");
    let at = start + 4 * index;
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
    std::fs::write(path, bytes).unwrap();
}

/// Rewrites the scene record of the saved scene at `path` through `edit`, keeping its tensors.
fn rewrite_record(path: &Path, edit: impl Fn(&str) -> String) {
    let bytes = std::fs::read(path).unwrap();
    let (_, metadata) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
    let record = metadata.metadata().as_ref().unwrap()[dggt_scene::saved::METADATA_KEY].clone();
    let edited = edit(&record);
    assert_ne!(edited, record, "the edit changes the record");
    let tensors = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let views: Vec<_> = tensors.tensors();
    let metadata = std::collections::HashMap::from([(dggt_scene::saved::METADATA_KEY.to_string(), edited)]);
    let out = safetensors::serialize(views, Some(metadata)).unwrap();
    std::fs::write(path, out).unwrap();
}
