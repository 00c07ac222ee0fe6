//! Parity with the release: the tiny model of `shared/parity/dggt_tiny_s3_56x70`, built from its
//! `config.json`, loaded from its `weights.safetensors` and run on its inputs, must reproduce the reference
//! outputs within max(1e-4 absolute, 1e-4 x max|reference|).
//!
//! The folder is read in place (`../../../shared/parity/dggt_tiny_s3_56x70` from this crate), or from
//! `$DGGT_PARITY_DIR/dggt_tiny_s3_56x70` when that variable names the shared parity folder.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::OnceLock;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics, PixelConvention, PoseEncoding, unproject_depth_map};
use dggt_model::{Dggt, DggtOutput, ModelConfig, ModelError};
use safetensors::SafeTensors;

const TOLERANCE: f32 = 1e-4;

fn parity_dir() -> PathBuf {
    let root = match std::env::var_os("DGGT_PARITY_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/parity"),
    };
    let dir = root.join("dggt_tiny_s3_56x70");
    assert!(
        dir.join("config.json").is_file(),
        "parity vectors not found at {} (set DGGT_PARITY_DIR to the shared parity folder)",
        dir.display()
    );
    dir
}

/// A host copy of a reference tensor.
struct Reference {
    shape: Vec<usize>,
    values: Vec<f32>,
}

fn read_safetensors(name: &str) -> HashMap<String, Reference> {
    let path = parity_dir().join(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    let file = SafeTensors::deserialize(&bytes).unwrap_or_else(|e| panic!("parsing {}: {e}", path.display()));
    file.tensors()
        .into_iter()
        .map(|(name, view)| {
            assert_eq!(view.dtype(), safetensors::Dtype::F32, "{name} is not f32");
            let values = view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
            (name, Reference { shape: view.shape().to_vec(), values })
        })
        .collect()
}

fn config() -> ModelConfig {
    ModelConfig::from_parity_json(parity_dir().join("config.json")).expect("parity config.json")
}

/// The model, its reference outputs and one forward pass, shared by the tests.
struct Run {
    model: Dggt,
    /// How many tensors the safetensors load applied.
    report_applied: usize,
    outputs: HashMap<String, Reference>,
    forward: DggtOutput,
}

fn run() -> &'static Run {
    static RUN: OnceLock<Run> = OnceLock::new();
    RUN.get_or_init(|| {
        let device = Device::flex();
        let (model, report) = Dggt::from_checkpoint(&config(), parity_dir().join("weights.safetensors"), &device)
            .expect("loading the parity weights");
        let inputs = read_safetensors("inputs.safetensors");
        let images = &inputs["images"];
        let shape: [usize; 5] = images.shape.clone().try_into().expect("images are [B, S, 3, H, W]");
        let images = Tensor::<5>::from_data(TensorData::new(images.values.clone(), shape), &device);
        let forward = model.forward(images).expect("forward pass");
        Run { model, report_applied: report.applied.len(), outputs: read_safetensors("outputs.safetensors"), forward }
    })
}

/// Compares tensors by name and prints one table; fails listing every tensor out of tolerance.
#[derive(Default)]
struct Comparison {
    rows: Vec<(String, Vec<usize>, f32, f32, bool)>,
}

impl Comparison {
    fn check<const D: usize>(&mut self, name: &str, actual: Tensor<D>) {
        let reference = run().outputs.get(name).unwrap_or_else(|| panic!("no reference output {name}"));
        let shape = actual.dims().to_vec();
        assert_eq!(shape, reference.shape, "{name}: shape");
        let values: Vec<f32> = actual.into_data().try_to_vec().expect("f32 output");
        let max_ref = reference.values.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let max_abs = values.iter().zip(&reference.values).fold(0.0f32, |m, (a, r)| m.max((a - r).abs()));
        assert!(values.iter().all(|v| v.is_finite()), "{name}: non-finite output");
        let ok = max_abs <= TOLERANCE.max(TOLERANCE * max_ref);
        self.rows.push((name.to_string(), shape, max_abs, max_abs / max_ref.max(f32::MIN_POSITIVE), ok));
    }

    fn finish(self, title: &str) {
        // One print per table, so that tables of tests running in parallel do not interleave.
        let mut table =
            format!("\n{title}\n{:<36} {:<18} {:>12} {:>12}\n", "tensor", "shape", "max abs err", "max rel err");
        for (name, shape, abs, rel, ok) in &self.rows {
            let flag = if *ok { "" } else { "  FAIL" };
            table += &format!("{name:<36} {:<18} {abs:>12.3e} {rel:>12.3e}{flag}\n", format!("{shape:?}"));
        }
        print!("{table}");
        let failed: Vec<&str> = self.rows.iter().filter(|r| !r.4).map(|r| r.0.as_str()).collect();
        assert!(failed.is_empty(), "out of tolerance: {failed:?}");
    }
}

#[test]
fn config_json_matches_tiny_preset() {
    assert_eq!(config(), ModelConfig::tiny());
}

#[test]
fn dino_matches_release() {
    let run = run();
    let out = &run.forward.aggregator;
    let [rows, cols] = out.grid;
    let mut cmp = Comparison::default();
    let height = rows * 14;
    let width = cols * 14;
    cmp.check("dino.pos_embed_interp", run.model.aggregator.patch_embed.interpolated_pos_embed(height, width));
    cmp.check("dino.prepared_tokens", out.dino.prepared_tokens.clone());
    let last = out.dino.layers.last().unwrap().clone();
    let [frames, _, c] = last.dims();
    cmp.check("image_feature", last.reshape([1, frames, rows, cols, c]));
    cmp.finish("DINO patch embedding");
}

#[test]
fn aggregator_matches_release() {
    let out = &run().forward.aggregator;
    assert_eq!(run().outputs["agg.patch_start_idx"].values, vec![out.patch_start_idx as f32]);
    let mut cmp = Comparison::default();
    for i in 0..out.output_list.len() {
        cmp.check(&format!("agg.output_list.{i}"), out.output_list[i].clone());
        cmp.check(&format!("agg.output_list_with_tokens.{i}"), out.output_with_dino_tokens(i));
        cmp.check(&format!("agg.dino_token_list.{i}"), out.dino_token_list[i].clone());
    }
    cmp.finish("aggregator");
}

#[test]
fn camera_head_matches_release() {
    let run = run();
    let camera = &run.forward.camera;
    let last = run.forward.aggregator.output_list.last().unwrap().clone();
    let stack = |list: &Vec<Tensor<3>>| Tensor::stack::<4>(list.clone(), 0);
    let mut cmp = Comparison::default();
    cmp.check("camera.token_norm_out", run.model.camera_head.token_norm_out(last));
    cmp.check("camera.pose_deltas", stack(&camera.deltas));
    cmp.check("camera.pose_preact", stack(&camera.preactivations));
    cmp.check("camera.pose_enc_list", stack(&camera.encodings));
    for (i, encoding) in camera.encodings.iter().enumerate() {
        cmp.check(&format!("camera.pose_enc_iter.{i}"), encoding.clone());
    }
    cmp.check("pose_enc", camera.pose_encoding());
    cmp.finish("camera head");
}

#[test]
fn every_built_weight_is_consumed() {
    let device = Device::flex();
    let path = parity_dir().join("weights.safetensors");
    let (model, report) = Dggt::from_checkpoint(&config(), &path, &device).expect("loading");
    let weights = read_safetensors("weights.safetensors");
    let prefixes = model.built_prefixes();
    let built = |name: &str| prefixes.iter().any(|p| name.starts_with(p));
    let expected = weights.keys().filter(|k| built(k)).count();
    assert_eq!(report.applied.len(), expected, "every checkpoint tensor under {prefixes:?} is applied");
    let stray: Vec<&String> = report.unused.iter().filter(|k| built(k)).collect();
    assert!(stray.is_empty(), "unconsumed tensors under built prefixes: {stray:?}");
    // Everything else in the file belongs to the tracker, which is not built.
    assert_eq!(report.unused.len(), weights.len() - expected);
    assert!(report.unused.iter().all(|k| k.starts_with("track_head.")), "{:?}", report.unused);
}

#[test]
fn shape_mismatch_names_tensor_and_shapes() {
    let mut config = config();
    config.camera_head.pose_branch[1] = 48;
    let device = Device::flex();
    let error = Dggt::from_checkpoint(&config, parity_dir().join("weights.safetensors"), &device)
        .expect_err("a mismatching network must not load");
    match &error {
        ModelError::ShapeMismatch { name, expected, found } => {
            assert!(name.starts_with("camera_head.pose_branch.fc"), "{name}");
            assert_ne!(expected, found);
        }
        other => panic!("expected a shape mismatch, got {other}"),
    }
    let message = error.to_string();
    println!("{message}");
    assert!(message.contains("camera_head.pose_branch.fc") && message.contains("48"), "{message}");
}

/// Checks a DPT pass's internals (where the vectors carry them) and raw output.
fn check_dpt(cmp: &mut Comparison, head: &str, dpt: &dggt_model::dpt::DptOutput, internals: bool) {
    if internals {
        for (i, map) in dpt.resized.iter().enumerate() {
            cmp.check(&format!("dbg.{head}.resize.{i}"), map.clone());
        }
        cmp.check(&format!("dbg.{head}.output_conv1"), dpt.fused.clone());
        cmp.check(&format!("dbg.{head}.head_in"), dpt.head_in.clone());
    }
    if head != "point_head" && head != "semantic_head" {
        cmp.check(&format!("{head}.raw"), dpt.raw.clone());
    }
}

#[test]
fn depth_and_point_heads_match_release() {
    let out = &run().forward;
    let mut cmp = Comparison::default();
    check_dpt(&mut cmp, "depth_head", &out.depth.dpt, true);
    cmp.check("depth", out.depth.prediction.clone());
    cmp.check("depth_conf", out.depth.confidence.clone());
    check_dpt(&mut cmp, "point_head", &out.points.dpt, false);
    cmp.check("world_points", out.points.prediction.clone());
    cmp.check("world_points_conf", out.points.confidence.clone());
    cmp.finish("depth and point heads");
}

#[test]
fn gaussian_head_matches_release() {
    let gaussians = run().forward.gaussians.as_ref().expect("the tiny DGGT has a Gaussian head");
    let maps = &gaussians.maps;
    let mut cmp = Comparison::default();
    check_dpt(&mut cmp, "gs_head", &gaussians.dpt, true);
    cmp.check("gs_map", maps.gs_map());
    cmp.check("gs.rgb", maps.rgb.clone());
    cmp.check("gs.opacity", maps.opacity.clone());
    cmp.check("gs.scale", maps.scale.clone());
    cmp.check("gs.rotation", maps.rotation.clone());
    cmp.check("gs.lifespan_raw", maps.lifespan_raw.clone());
    cmp.finish("Gaussian head");
}

/// `gs_conf = 1 / (relu(x) + 1e-6)` is ill-conditioned near `x = 0` (a 1e-6 error in `x` at `x ~ 1e-3` is a
/// 1e-3 relative error), so its reciprocal `relu(x) + 1e-6` is compared with the usual tolerance.
#[test]
fn gaussian_lifespan_matches_release() {
    let gaussians = run().forward.gaussians.as_ref().expect("the tiny DGGT has a Gaussian head");
    let actual: Vec<f32> = gaussians.maps.lifespan.clone().into_data().try_to_vec().unwrap();
    let reference = &run().outputs["gs_conf"];
    assert_eq!(gaussians.maps.lifespan.dims().to_vec(), reference.shape);
    let worst_reciprocal =
        actual.iter().zip(&reference.values).fold(0.0f32, |m, (a, r)| m.max((1.0 / a - 1.0 / r).abs()));
    let worst_relative = actual.iter().zip(&reference.values).fold(0.0f32, |m, (a, r)| m.max((a - r).abs() / r));
    let saturated = |v: &[f32]| v.iter().filter(|&&g| g == 1e6).count();
    println!(
        "\ngs_conf: max |1/actual - 1/reference| {worst_reciprocal:.3e}, max relative {worst_relative:.3e}, \
         {} of {} at 1e6 (reference {})",
        saturated(&actual),
        actual.len(),
        saturated(&reference.values)
    );
    assert!(worst_reciprocal <= TOLERANCE, "gs_conf reciprocal error {worst_reciprocal}");
}

#[test]
fn instance_and_semantic_heads_match_release() {
    let out = &run().forward;
    let instance = out.instance.as_ref().expect("the tiny DGGT has an instance head");
    let semantic = out.semantic.as_ref().expect("the tiny DGGT has a semantic head");
    let mut cmp = Comparison::default();
    check_dpt(&mut cmp, "instance_head", &instance.dpt, true);
    cmp.check("dynamic_conf", instance.prediction.clone());
    cmp.check("instance.conf_unused", instance.confidence.clone());
    check_dpt(&mut cmp, "semantic_head", &semantic.dpt, false);
    cmp.check("semantic_logits", semantic.prediction.clone());
    cmp.finish("instance and semantic heads");
}

/// The `torch.save` state dicts (CPU storages, and storages tagged `cuda:0` as the released checkpoint was
/// saved) load to the same network as the safetensors file.
#[test]
fn pytorch_checkpoints_load_the_same_network() {
    let inputs = read_safetensors("inputs.safetensors");
    let images = &inputs["images"];
    let shape: [usize; 5] = images.shape.clone().try_into().expect("images are [B, S, 3, H, W]");
    for file in ["weights.pt", "weights_cuda_storage.pt"] {
        let device = Device::flex();
        let (model, report) = Dggt::from_checkpoint(&config(), parity_dir().join(file), &device)
            .unwrap_or_else(|e| panic!("loading {file}: {e}"));
        assert_eq!(report.applied.len(), run().report_applied, "{file}: applied tensors");
        let images = Tensor::<5>::from_data(TensorData::new(images.values.clone(), shape), &device);
        let out = model.forward(images).expect("forward pass");
        let mut cmp = Comparison::default();
        cmp.check("pose_enc", out.camera.pose_encoding());
        cmp.check("depth_head.raw", out.depth.dpt.raw);
        cmp.check("gs_head.raw", out.gaussians.expect("Gaussian head").dpt.raw);
        cmp.check("instance_head.raw", out.instance.expect("instance head").dpt.raw);
        cmp.finish(&format!("loaded from {file}"));
    }
}

/// Decodes the predicted pose encodings into cameras.
fn predicted_cameras(out: &DggtOutput, size: ImageSize) -> Vec<(CameraFromWorld, PinholeIntrinsics)> {
    let encodings: Vec<f32> = out.camera.pose_encoding().into_data().try_to_vec().unwrap();
    encodings
        .chunks(9)
        .map(|frame| {
            let values: [f64; 9] = std::array::from_fn(|i| frame[i] as f64);
            PoseEncoding::from_array(values).decode(size).expect("valid encoding")
        })
        .collect()
}

fn image_size(out: &DggtOutput) -> ImageSize {
    let [rows, cols] = out.aggregator.grid;
    ImageSize::new((cols * 14) as u32, (rows * 14) as u32).unwrap()
}

/// The predicted encoding decodes (with `dggt-geom`) to the release's extrinsics and intrinsics, and the
/// predicted depth unprojects (at integer pixel coordinates, as the release does) to its Gaussian means.
#[test]
fn predictions_decode_to_release_cameras_and_means() {
    let out = &run().forward;
    let size = image_size(out);
    let depth: Vec<f32> = out.depth.prediction.clone().into_data().try_to_vec().unwrap();
    let (mut extrinsics, mut intrinsics, mut means) = (Vec::<f32>::new(), Vec::<f32>::new(), Vec::<f32>::new());
    let cameras = predicted_cameras(out, size);
    for ((camera_from_world, k), depth) in cameras.iter().zip(depth.chunks(size.area())) {
        extrinsics.extend(camera_from_world.to_rows()[..3].iter().flatten().map(|&v| v as f32));
        intrinsics.extend(k.to_rows_f32().iter().flatten());
        let points = unproject_depth_map(depth, size, k, camera_from_world, PixelConvention::Integer).unwrap();
        means.extend(points.iter().flat_map(|p| p.to_array()).map(|v| v as f32));
    }
    let frames = cameras.len();
    let (h, w) = (size.height as usize, size.width as usize);
    let device = Device::flex();
    let tensor = |values: Vec<f32>, shape: [usize; 4]| Tensor::<4>::from_data(TensorData::new(values, shape), &device);
    let mut cmp = Comparison::default();
    cmp.check("extrinsics", tensor(extrinsics, [1, frames, 3, 4]));
    cmp.check("intrinsics", tensor(intrinsics, [1, frames, 3, 3]));
    cmp.check("means.world", tensor(means, [frames, h, w, 3]).unsqueeze::<5>());
    cmp.finish("decoded cameras and Gaussian means");
}

/// The sky Gaussians coloured from the input images with the predicted cameras.
#[test]
fn sky_model_matches_release() {
    let run = run();
    let out = &run.forward;
    let sky = run.model.sky_model.as_ref().expect("the tiny DGGT has a sky model");
    let size = image_size(out);
    let cameras = predicted_cameras(out, size);
    let inputs = read_safetensors("inputs.safetensors");
    let images = &inputs["images"];
    let [_, s, c, h, w]: [usize; 5] = images.shape.clone().try_into().unwrap();
    let device = Device::flex();
    let images = Tensor::<4>::from_data(TensorData::new(images.values.clone(), [s, c, h, w]), &device);

    // Projection: visibility exactly; pixels where the point is seen (behind a camera they are clamped
    // garbage, and at grazing depths x / z amplifies the f32 rounding of the reference), depths everywhere.
    let projection = sky.project(&cameras, size);
    let reference = |name: &str| &run.outputs[name].values;
    let (in_front, view_mask) = (reference("sky.in_front"), reference("sky.view_mask"));
    let (pixels, depth) = (reference("sky.pixel_locations"), reference("sky.proj_depth"));
    let n = projection.points;
    let (mut worst_pixel, mut worst_depth) = (0.0f64, 0.0f64);
    for (i, ((pixel, z), seen)) in projection.pixels.iter().zip(&projection.depth).zip(&projection.seen).enumerate() {
        let (view, point) = (i / n, i % n);
        assert_eq!(*z > 0.0, in_front[i] == 1.0, "point {point} view {view}: in front");
        assert_eq!(*seen, view_mask[point * s + view] == 1.0, "point {point} view {view}: seen");
        worst_depth = worst_depth.max((z - depth[i] as f64).abs());
        if *seen {
            for (axis, value) in pixel.iter().enumerate() {
                worst_pixel = worst_pixel.max((value - pixels[2 * i + axis] as f64).abs());
            }
        }
    }
    println!(
        "\nsky projection: max pixel error of seen points {worst_pixel:.3e} px, max depth error {worst_depth:.3e}"
    );
    assert!(worst_pixel < 1e-3 && worst_depth < 1e-3, "sky projection out of tolerance");

    let gaussians = sky.gaussians(images, &cameras);
    let expected_index: Vec<usize> = reference("sky.visible_index").iter().map(|&i| i as usize).collect();
    assert_eq!(gaussians.visible_index, expected_index);
    let mut cmp = Comparison::default();
    cmp.check("sky.rgb_mean", gaussians.rgb_mean.clone());
    cmp.check("sky.bg_field_out", gaussians.field_out.clone());
    cmp.check("sky.colors", gaussians.colors.clone());
    cmp.check("sky.means", gaussians.means.clone());
    cmp.check("sky.scales", gaussians.scales.clone());
    cmp.check("sky.quats", gaussians.quats.clone());
    cmp.check("sky.opacities", gaussians.opacities.clone());
    cmp.finish("sky model");
}
