//! Parity with the release: the tiny model of `shared/parity/dggt_tiny_s3_56x70`, built from its
//! `config.json`, loaded from its weights and run on its inputs, reproduces every reference output, renders
//! included ([`dggt_parity::network`] does the comparing), and a report fails on any output it did not
//! compare.
//!
//! The folder is read in place (`../../../shared/parity/dggt_tiny_s3_56x70` from this crate), or from
//! `$DGGT_PARITY_DIR/dggt_tiny_s3_56x70` when that variable names the shared parity folder.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use burn::tensor::Device;
use dggt_model::{Dggt, ModelConfig, ModelError};
use dggt_parity::network::{NetworkRun, run_parity};
use dggt_parity::vectors::read_tensors;
use dggt_parity::{ParityReport, ParityVectors, Status};

fn parity_dir() -> PathBuf {
    dggt_test_data::parity("dggt_tiny_s3_56x70")
}

fn vectors() -> &'static ParityVectors {
    static VECTORS: OnceLock<ParityVectors> = OnceLock::new();
    VECTORS.get_or_init(|| ParityVectors::open(parity_dir()).expect("opening the parity vectors"))
}

/// The run from `weights.safetensors`, shared by the tests.
fn run() -> &'static NetworkRun {
    static RUN: OnceLock<NetworkRun> = OnceLock::new();
    RUN.get_or_init(|| {
        let weights = parity_dir().join("weights.safetensors");
        run_parity(vectors(), &weights, &Device::flex()).expect("running the parity vectors")
    })
}

fn report() -> &'static ParityReport {
    &run().report
}

/// Asserts that every row whose name starts with one of `prefixes` (and at least one) passes.
fn assert_group_passes(title: &str, prefixes: &[&str]) {
    let rows: Vec<_> =
        report().rows.iter().filter(|row| prefixes.iter().any(|prefix| row.name.starts_with(prefix))).collect();
    assert!(!rows.is_empty(), "{title}: no reference outputs named {prefixes:?}");
    let failed: Vec<&str> = rows.iter().filter(|row| row.status != Status::Pass).map(|row| row.name.as_str()).collect();
    assert!(failed.is_empty(), "{title}: not passing: {failed:?}\n{}", report());
}

#[test]
fn config_json_matches_tiny_preset() {
    assert_eq!(vectors().config, ModelConfig::tiny());
}

#[test]
fn every_output_is_reproduced() {
    let report = report();
    println!("\n{report}{}", report.summary());
    assert!(report.passed(), "out of tolerance: {:?}", report.failed().map(|row| &row.name).collect::<Vec<_>>());
    assert_eq!(report.rows.len(), vectors().outputs.len(), "one row per reference output");
    for row in &report.rows {
        assert_eq!(row.status, Status::Pass, "{}", row.name);
    }
}

/// The same vectors on burn's wgpu device (CI: Mesa's software Vulkan driver): the GPU route of the network (burn's
/// fused kernels, the DPT's convolutions as matrix products, the CubeCL rasteriser for the renders) reproduces every
/// reference output within the same tolerances as the CPU.
#[cfg(feature = "wgpu")]
#[test]
fn every_output_is_reproduced_on_wgpu() {
    let weights = parity_dir().join("weights.safetensors");
    let device = Device::wgpu(burn::tensor::DeviceKind::default());
    let report = run_parity(vectors(), &weights, &device).expect("running the parity vectors on wgpu").report;
    println!("\n{report}{}", report.summary());
    let failed: Vec<&String> = report.failed().map(|row| &row.name).collect();
    assert!(report.passed(), "out of tolerance on wgpu: {failed:?}");
    assert_eq!(report.rows.len(), vectors().outputs.len(), "one row per reference output");
}

#[test]
fn dino_and_aggregator_match_release() {
    assert_group_passes("DINO and aggregator", &["dino.", "image_feature", "agg."]);
}

#[test]
fn camera_head_matches_release() {
    assert_group_passes("camera head", &["camera.", "pose_enc"]);
}

#[test]
fn dense_heads_match_release() {
    let heads = ["dbg.", "depth", "world_points", "gs_map", "gs.", "gs_conf", "dynamic_conf", "instance", "semantic"];
    assert_group_passes("DPT heads", &heads);
}

/// `gs_conf` is ill-conditioned near `relu(x) = 0`, so it is compared through its reciprocal.
#[test]
fn gaussian_lifespan_is_compared_through_its_reciprocal() {
    let row = report().row("gs_conf").expect("the vectors hold gs_conf");
    assert_eq!(row.status, Status::Pass);
    assert_eq!(row.note.as_deref(), Some("compared as 1/gs_conf"));
    assert!(row.tolerance.unwrap() < 1e-3, "the reciprocal is at most ~2, so the tolerance stays absolute-sized");
}

#[test]
fn predictions_decode_to_release_cameras_and_means() {
    assert_group_passes("decoded cameras and Gaussian means", &["extrinsic", "intrinsics", "means."]);
}

#[test]
fn sky_model_matches_release() {
    assert_group_passes("sky model", &["sky."]);
    let pixels = report().row("sky.pixel_locations").unwrap();
    assert_eq!(
        pixels.note.as_deref(),
        Some("compared where the point is seen: in front of the camera, inside the image")
    );
}

/// A perturbed reference is caught, and a name the port does not know is listed as not compared: a failure.
#[test]
fn perturbed_and_unknown_outputs_are_reported() {
    let mut vectors = vectors().clone();
    let (_, depth) = vectors.outputs.iter_mut().find(|(name, _)| name == "depth").expect("depth");
    depth.values[17] += 1e-2;
    let unknown = vectors.outputs[0].1.clone();
    vectors.outputs.push(("track.coords".into(), unknown));
    let weights = vectors.default_weights().unwrap();
    let report = run_parity(&vectors, &weights, &Device::flex()).unwrap().report;
    assert!(!report.passed());
    let failed: Vec<&str> = report.failed().map(|row| row.name.as_str()).collect();
    assert_eq!(failed, ["depth", "track.coords"]);
    let depth = report.row("depth").unwrap();
    assert_eq!(depth.status, Status::OutOfTolerance);
    assert!(depth.max_abs.unwrap() > 9e-3 && depth.max_abs.unwrap() < 1.1e-2, "{depth:?}");
    assert_eq!(report.row("track.coords").unwrap().status, Status::Unknown);
}

/// An outputs file holding a tensor the port cannot reproduce fails the run, though every other output passes.
#[test]
fn an_output_the_port_cannot_reproduce_fails_the_report() {
    let copy = tempfile::tempdir().unwrap();
    for file in ["config.json", "inputs.safetensors", "weights.safetensors"] {
        std::fs::copy(parity_dir().join(file), copy.path().join(file)).unwrap();
    }
    let mut outputs = read_tensors(parity_dir().join("outputs.safetensors")).unwrap();
    outputs.truncate(3);
    outputs.push(("track_head.coords".into(), outputs[0].1.clone()));
    write_f32_tensors(&copy.path().join("outputs.safetensors"), &outputs);
    let vectors = ParityVectors::open(copy.path()).unwrap();
    let report = run_parity(&vectors, &copy.path().join("weights.safetensors"), &Device::flex()).unwrap().report;
    assert_eq!(report.rows.len(), 4);
    assert!(report.rows[..3].iter().all(|row| row.status == Status::Pass), "{report}");
    assert_eq!(report.rows[3].status, Status::Unknown);
    assert!(!report.passed(), "{report}");
    assert!(report.summary().contains(" 1 fail, 1 of them not compared"), "{}", report.summary());
}

/// Writes `tensors` as an `f32` safetensors file, in their order.
fn write_f32_tensors(path: &Path, tensors: &[(String, dggt_parity::HostTensor)]) {
    let bytes: Vec<Vec<u8>> =
        tensors.iter().map(|(_, t)| t.values.iter().flat_map(|v| v.to_le_bytes()).collect()).collect();
    let views = tensors.iter().zip(&bytes).map(|((name, tensor), data)| {
        let view = safetensors::tensor::TensorView::new(safetensors::Dtype::F32, tensor.shape.clone(), data);
        (name.as_str(), view.unwrap())
    });
    safetensors::serialize_to_file(views, None, path).unwrap();
}

#[test]
fn every_built_weight_is_consumed() {
    let device = Device::flex();
    let path = parity_dir().join("weights.safetensors");
    let (model, report) = Dggt::from_checkpoint(&vectors().config, &path, &device).expect("loading");
    let weights = read_tensors(&path).expect("reading the weights");
    let prefixes = model.built_prefixes();
    let built = |name: &str| prefixes.iter().any(|p| name.starts_with(p));
    let expected = weights.iter().filter(|(k, _)| built(k)).count();
    assert_eq!(report.applied.len(), expected, "every checkpoint tensor under {prefixes:?} is applied");
    let stray: Vec<&String> = report.unused.iter().filter(|k| built(k)).collect();
    assert!(stray.is_empty(), "unconsumed tensors under built prefixes: {stray:?}");
    // Everything else in the file belongs to the tracker, which is not built.
    assert_eq!(report.unused.len(), weights.len() - expected);
    assert!(report.unused.iter().all(|k| k.starts_with("track_head.")), "{:?}", report.unused);
}

#[test]
fn shape_mismatch_names_tensor_and_shapes() {
    let mut config = vectors().config.clone();
    config.camera_head.pose_branch[1] = 48;
    let device = Device::flex();
    let error = Dggt::from_checkpoint(&config, parity_dir().join("weights.safetensors"), &device)
        .expect_err("a mismatching network must not load");
    match &error {
        ModelError::ShapeMismatches(mismatches) => {
            assert_eq!(mismatches.len(), 3, "fc1 weight and bias, fc2 weight: {mismatches:?}");
            assert!(mismatches.iter().all(|m| m.starts_with("camera_head.pose_branch.fc")), "{mismatches:?}");
        }
        other => panic!("expected shape mismatches, got {other}"),
    }
    let message = error.to_string();
    println!("{message}");
    assert!(message.contains("camera_head.pose_branch.fc") && message.contains("48"), "{message}");
}

/// The `torch.save` state dicts (CPU storages, and storages tagged `cuda:0` as the released checkpoint was
/// saved) load to the same network as the safetensors file.
#[test]
fn pytorch_checkpoints_load_the_same_network() {
    for file in ["weights.pt", "weights_cuda_storage.pt"] {
        let pt = run_parity(vectors(), &parity_dir().join(file), &Device::flex())
            .unwrap_or_else(|e| panic!("running from {file}: {e}"));
        assert_eq!(pt.load.applied.len(), run().load.applied.len(), "{file}: applied tensors");
        assert!(pt.report.passed(), "{file}:\n{}", pt.report);
    }
}

#[test]
fn missing_folder_is_a_clear_error() {
    let error = ParityVectors::open("/no/such/vectors").expect_err("no folder");
    assert_eq!(error.to_string(), "parity vectors at /no/such/vectors: no such folder");
    let empty = std::env::temp_dir().join(format!("dggt-parity-empty-{}", std::process::id()));
    std::fs::create_dir_all(&empty).unwrap();
    let error = ParityVectors::open(&empty).expect_err("no files").to_string();
    std::fs::remove_dir(&empty).unwrap();
    assert!(error.contains("config.json is missing"), "{error}");
}

/// A fresh sky model's buffers (Fibonacci hemisphere, neighbour scales, unit opacity, identity rotations) are
/// the ones the release stores in its checkpoints.
#[test]
fn fresh_sky_buffers_match_the_release() {
    use burn::module::Param;
    use dggt_model::sky::SkyModel;
    let config = vectors().config.sky_model.clone().expect("the tiny model has a sky");
    let sky = SkyModel::initialised(&config, &Device::flex());
    let stored = read_tensors(parity_dir().join("weights.safetensors")).unwrap();
    let compare = |name: &str, buffer: &Param<burn::tensor::Tensor<2>>, tolerance: f32| {
        let (_, reference) = stored.iter().find(|(key, _)| key == name).unwrap_or_else(|| panic!("{name} stored"));
        let ours: Vec<f32> = buffer.val().into_data().try_into_vec().unwrap();
        assert_eq!(ours.len(), reference.values.len(), "{name}");
        let worst = ours.iter().zip(&reference.values).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= tolerance, "{name}: max abs difference {worst}");
    };
    compare("sky_model.bg_pcd", &sky.bg_pcd, 2e-5 * config.radius as f32);
    compare("sky_model.bg_scales", &sky.bg_scales, 1e-5);
    compare("sky_model.bg_opacity", &sky.bg_opacity, 0.0);
    compare("sky_model.bg_quat", &sky.bg_quat, 0.0);
}
