//! `dggt reconstruct` end to end on the bundled fixture (CPU): a tiny network trained for a few steps, then
//! one reconstruction from its checkpoint, checked file by file and render by render against the trainer's own
//! renders of the same weights; and the errors bad inputs give.
//!
//! Nothing here depends on how well the network trained: a few steps from scratch land anywhere, and where they
//! land moves with every rounding difference between processors (AVX2, FMA, AVX-512). What must hold on any
//! processor is that the reconstruction pipeline (checkpoint files, preprocessing, chunked forward pass, scene
//! assembly, rasteriser, PNG export) renders exactly what training renders from the same weights.

use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::tensor::Device;
use dggt_formats::cameras_json::{CameraRecord, read_cameras_json};
use dggt_formats::colmap::{read_cameras_txt, read_images_txt};
use dggt_formats::depth::{read_depth_npy, read_depth_png16};
use dggt_formats::images::read_rgb_png;
use dggt_formats::masks::read_mask_png;
use dggt_formats::nerfstudio::read_transforms;
use dggt_formats::ply::{INRIA_PROPERTIES, read_ply};
use dggt_infer::{Architecture, CameraSource};
use dggt_reconstruct::align::pose_error;
use dggt_reconstruct::{ReconstructOptions, Summary, TimeRequest, reconstruct};
use dggt_train::{RunOptions, Start, TrainConfig, Trainer};

/// Training steps of the checkpoint under test: enough for every head to have moved off its initial draw.
const TRAIN_STEPS: u64 = 4;
/// The frames of camera 0 reconstructed, which the trainer's validation also renders.
const FRAMES: usize = 8;
/// A reconstruction render against the trainer's render of the same view, in 8-bit levels: the largest
/// difference of any channel of any pixel, and the mean over all of them. Both run the same arithmetic on the
/// same processor, so they can differ only where the order of a floating-point sum does (the reconstruction
/// runs the dense heads a few frames at a time), far below a level except for a value on a rounding boundary;
/// they were identical where this was written. A wrong camera, time, colour order, preprocessing or
/// rasteriser setting moves most pixels: the release's `eps2d` instead of the run's gave up to 102 levels,
/// 12.8 on average.
const MAX_LEVELS: u8 = 3;
const MEAN_LEVELS: f64 = 0.05;

fn repo() -> PathBuf {
    dggt_test_data::repo_root()
}

fn fixture() -> PathBuf {
    dggt_test_data::fixture("synth-s0")
}

/// The tiny overfit configuration at 56 pixels wide, front camera, four inputs and a few steps; its final
/// validation renders the reconstruction's views (the first eight frames as inputs and as targets) from the
/// predicted cameras, as the reconstruction does.
fn train_config(out: &Path) -> TrainConfig {
    let mut config = TrainConfig::load(&repo().join("configs/tiny-overfit.toml")).expect("tiny-overfit.toml loads");
    config.data.scene = fixture();
    config.data.preprocess.target_width = 56;
    config.sampler.min_inputs = 4;
    config.sampler.max_inputs = 4;
    config.render.render_inputs = false;
    config.optim.warmup_steps = 2;
    config.run.steps = TRAIN_STEPS;
    let mut config = config.unattended(out);
    config.render.cameras = CameraSource::Predicted;
    config.data.validation.inputs = (0..FRAMES).collect();
    config.data.validation.targets = (0..FRAMES).collect();
    config
}

#[test]
fn reconstructs_the_fixture_from_a_trained_checkpoint() {
    let started = Instant::now();
    let run = tempfile::tempdir().unwrap();
    let config = train_config(run.path());
    let mut trainer = Trainer::new(config.clone(), vec![Device::flex()], Start::Fresh).unwrap();
    let trained = trainer.run(RunOptions::default()).unwrap();
    assert!(trained.checkpoint.is_some(), "the run ends with a checkpoint");
    assert_eq!(trained.validation.as_ref().map(|v| v.views.len()), Some(FRAMES), "the final validation");
    eprintln!("trained {TRAIN_STEPS} steps in {:.1} s", started.elapsed().as_secs_f64());
    // The reconstruction assembles and rasterises as training did (`render.eps2d`, the dynamic blend).
    let settings = run.path().join("train.toml");
    std::fs::write(&settings, toml::to_string(&config).unwrap()).unwrap();

    // The run folder is accepted (its latest checkpoint is used), at the width it records.
    let out = tempfile::tempdir().unwrap();
    let out = out.path();
    let mut options = ReconstructOptions::new(fixture(), run.path(), out);
    options.architecture = Some(Architecture::Config(settings));
    options.cameras = Some(vec![0]);
    options.frames = Some(0..FRAMES);
    options.chunk_frames = 3;
    options.times = TimeRequest::Every(2);
    let summary = reconstruct(&options, &Device::flex()).unwrap();
    eprintln!("{summary}");

    let names: Vec<String> = (0..FRAMES).map(|f| format!("{f:03}_0")).collect();
    check_files(&summary, out, &names);
    check_gaussians(&summary, out);
    let records = check_cameras(out, &names);
    check_poses(&summary, &records);
    check_maps(out, &names);
    let validation = run.path().join(format!("validation/step-{TRAIN_STEPS:08}"));
    check_renders(&summary, out, &validation);
    check_instances(&summary, out);
    check_saved_scene(&summary, out);
    let elapsed = started.elapsed().as_secs_f64();
    eprintln!("total {elapsed:.1} s");
}

/// The moving objects listed: numbered in order, each seen at increasing times, its boxes well formed around
/// its centres, its first pose the identity, one residual per step; the same list in `summary.json`.
fn check_instances(summary: &Summary, out: &Path) {
    for (position, instance) in summary.instances.iter().enumerate() {
        assert_eq!(instance.id as usize, position, "instance ids number their positions");
        assert_eq!(instance.residuals.len() + 1, instance.appearances.len(), "{instance:?}");
        let first = &instance.appearances[0];
        assert_eq!((first.rotation_wxyz, first.translation), ([1.0, 0.0, 0.0, 0.0], [0.0; 3]), "{instance:?}");
        for pair in instance.appearances.windows(2) {
            assert!(pair[0].scene_time < pair[1].scene_time && pair[0].frame < pair[1].frame, "{instance:?}");
        }
        for appearance in &instance.appearances {
            assert!(appearance.pixels > 0 && appearance.views.iter().all(|&v| v < summary.views), "{appearance:?}");
            assert!(appearance.frame < FRAMES, "{appearance:?}");
            for axis in 0..3 {
                let (low, high, centre) = (appearance.box_min[axis], appearance.box_max[axis], appearance.centre[axis]);
                assert!(low <= centre && centre <= high, "{appearance:?}");
            }
        }
    }
    let on_disk: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(
        on_disk["instances"].as_array().map(Vec::len),
        Some(summary.instances.len()),
        "summary.json lists every instance"
    );
    eprintln!("{} moving objects", summary.instances.len());
}

/// The saved scene reads back with the summary's objects and renders the first input view as its render file
/// shows it (8-bit rounding apart).
fn check_saved_scene(summary: &Summary, out: &Path) {
    let scene = dggt_scene::load_scene(&out.join("scene.safetensors"), &Device::flex()).unwrap();
    assert_eq!(scene.views().len(), summary.views, "the scene holds every view of the summary");
    assert_eq!(
        scene.pixels.instances().map_or(0, |found| found.len()),
        summary.instances.len(),
        "the scene holds every instance of the summary"
    );
    let first = scene.views()[0];
    let target = dggt_scene::TargetView { rig_camera: first.rig_camera, time: first.time, camera: first.camera };
    let rgb: Vec<f32> = scene.render(&target).unwrap().rgb.into_data().try_into_vec().unwrap();
    let (_, written) = read_rgb_png(&out.join("renders/t0000_cam0.png")).unwrap();
    let largest = rgb.iter().zip(&written).map(|(a, b)| (a.clamp(0.0, 1.0) - b).abs()).fold(0.0f32, f32::max);
    assert!(largest <= 1.0 / 255.0 + 1e-6, "the saved scene renders frame 0 up to {largest} away from its file");
}

/// Every listed file exists, and the expected ones are listed.
fn check_files(summary: &Summary, out: &Path, names: &[String]) {
    // Every listed file exists, and the expected ones are listed.
    for file in &summary.files {
        assert!(out.join(file).is_file(), "{file} listed but not written");
    }
    let mut expected: Vec<String> = [
        "cameras.json",
        "transforms.json",
        "sparse/0/cameras.txt",
        "sparse/0/images.txt",
        "sparse/0/points3D.txt",
        "gaussians/static.ply",
        "gaussians/sky.ply",
        "scene.safetensors",
        "summary.json",
    ]
    .map(String::from)
    .to_vec();
    for name in names {
        for pattern in
            ["images/{}.png", "depth/{}.npy", "depth/{}.png", "depth/{}.json", "dynamic/{}.png", "sky/{}.png"]
        {
            expected.push(pattern.replace("{}", name));
        }
    }
    // Every(2) over 8 input frames: 7 intervals x 2 + the last = 15 times.
    assert_eq!(summary.times_s.len(), 15, "two times per interval and the last");
    for k in 0..15 {
        expected.push(format!("gaussians/dynamic_t{k:04}.ply"));
        expected.push(format!("renders/t{k:04}_cam0.png"));
    }
    for file in &expected {
        assert!(summary.files.contains(file) && out.join(file).is_file(), "{file} missing");
    }
    assert_eq!(summary.files.len(), expected.len(), "{:?}", summary.files);
    let on_disk: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(on_disk["frames"], FRAMES, "summary.json counts the input frames");
    assert_eq!(on_disk["checkpoint"]["format"], "trainer", "the run's checkpoint is the trainer's");
    assert!(on_disk["peak_memory_mib"].as_f64().unwrap() > 0.0, "a peak memory is recorded");
    assert!(on_disk["stages"].as_array().unwrap().len() >= 5, "at least the five stages timed");
}

/// PLY headers are INRIA's and vertex counts are the Gaussians kept.
fn check_gaussians(summary: &Summary, out: &Path) {
    let g = &summary.gaussians;
    assert_eq!(g.per_pixel, 8 * 56 * 42, "one Gaussian per pixel of 8 frames of 56 x 42");
    let ply = |file: &str| read_ply(&out.join(file)).unwrap();
    let statics = ply("gaussians/static.ply");
    assert_eq!(statics.properties, INRIA_PROPERTIES.map(String::from).to_vec(), "the INRIA PLY properties");
    assert_eq!(statics.count, g.static_kept, "static.ply holds the kept static Gaussians");
    // How many culling keeps depends on what the few steps learnt; the counts must be those of the files.
    assert!(g.static_kept <= g.per_pixel, "{g:?}");
    let cloud = statics.to_cloud().unwrap();
    assert!(cloud.opacities.iter().all(|&o| (1.0 / 255.0 - 1e-6..=1.0).contains(&o)), "opacities in [1/255, 1]");
    assert!(cloud.means.iter().flatten().all(|v| v.is_finite()), "finite means");
    assert_eq!(ply("gaussians/sky.ply").count, g.sky_kept, "sky.ply holds the kept sky Gaussians");
    assert!(g.sky_kept <= 60 * 60, "the overfit configuration's 60 x 60 sky Gaussians at most: {g:?}");
    for (k, &count) in g.dynamic_kept.iter().enumerate() {
        assert_eq!(
            ply(&format!("gaussians/dynamic_t{k:04}.ply")).count,
            count,
            "dynamic_t{k:04}.ply holds the frame's kept dynamic Gaussians"
        );
        assert!(count <= 56 * 42, "one view's pixels at most");
    }
}

/// The three camera formats agree with each other; returns the cameras.json records.
fn check_cameras(out: &Path, names: &[String]) -> Vec<CameraRecord> {
    // Cameras: the three formats agree with each other.
    let (convention, records) = read_cameras_json(&out.join("cameras.json")).unwrap();
    assert!(convention.axes.contains("OpenCV"), "cameras.json in the OpenCV convention");
    assert_eq!(
        records.iter().map(|r| r.name.clone()).collect::<Vec<_>>(),
        names,
        "cameras.json names the views in order"
    );
    let colmap_cameras = read_cameras_txt(&out.join("sparse/0/cameras.txt")).unwrap();
    let colmap_images = read_images_txt(&out.join("sparse/0/images.txt")).unwrap();
    let transforms = read_transforms(&out.join("transforms.json")).unwrap();
    assert_eq!(
        (colmap_cameras.len(), colmap_images.len(), transforms.len()),
        (8, 8, 8),
        "8 cameras, images and transforms"
    );
    for (i, record) in records.iter().enumerate() {
        assert_eq!(colmap_images[i].name, format!("{}.png", record.name), "COLMAP image {i} named after its view");
        let camera = colmap_cameras.iter().find(|c| c.id == colmap_images[i].camera_id).unwrap();
        let (a, b) = (camera.intrinsics, record.intrinsics);
        assert!([a.fx - b.fx, a.fy - b.fy, a.cx - b.cx, a.cy - b.cy].iter().all(|d| d.abs() < 1e-9), "{a:?} {b:?}");
        assert!(
            colmap_images[i].camera_from_world.max_abs_difference(&record.world_from_camera.inverse()) < 1e-6,
            "COLMAP pose {i} inverts the view's"
        );
        assert!(
            transforms[i].world_from_camera.max_abs_difference(&record.world_from_camera) < 1e-6,
            "transforms.json pose {i} is the view's"
        );
        assert!(out.join(&transforms[i].file_path).is_file(), "transforms.json image {i} exists");
    }
    records
}

/// The summary's pose error is that of the exported cameras against the fixture's, after similarity alignment.
fn check_poses(summary: &Summary, records: &[CameraRecord]) {
    let scene = dggt_data::open_scene(&fixture(), Some(0..FRAMES), Some(vec![0])).unwrap();
    let truth: Vec<_> = (0..FRAMES)
        .map(|f| scene.view(f, 0).world_from_camera.relative_to(&scene.view(0, 0).world_from_camera))
        .collect();
    let predicted: Vec<_> = records.iter().map(|r| r.world_from_camera).collect();
    assert!(predicted.iter().all(|pose| pose.translation().is_finite()), "{predicted:?}");
    let error = pose_error(&predicted, &truth).expect("distinct camera centres");
    eprintln!("{error:?}");
    assert!(error.centre_rmse.is_finite() && error.scale > 0.0, "{error:?}");
    let reported = summary.pose_error.as_ref().expect("scene exports report pose errors");
    assert!(
        (reported.centre_rmse - error.centre_rmse).abs() < 1e-9
            && (reported.rotation_max_deg - error.rotation_max_deg).abs() < 1e-6,
        "the summary reports the pose error of the written cameras"
    );
}

/// Depth in both formats agrees; maps have the network's size.
fn check_maps(out: &Path, names: &[String]) {
    // Depth in both formats agrees; maps have the network's size.
    for name in names {
        let (size, npy) = read_depth_npy(&out.join(format!("depth/{name}.npy"))).unwrap();
        assert_eq!((size.width, size.height), (56, 42), "depth .npy of the 56 x 42 network size");
        assert!(npy.iter().all(|d| d.is_finite() && *d > 0.0), "positive finite depths");
        let (_, png, meta) = read_depth_png16(&out.join(format!("depth/{name}.png"))).unwrap();
        // Rounded to the scale's multiples, and the smallest non-zero value where a depth is below half the scale
        // (a network trained briefly may span more than 16 bits of depth).
        let tolerance =
            |depth: f64| if depth < meta.scale / 2.0 { meta.scale } else { meta.scale / 2.0 + 1e-6 * depth };
        let off = npy.iter().zip(&png).find(|(a, b)| f64::from((**a - **b).abs()) > tolerance(f64::from(**a)));
        assert!(off.is_none(), "depth/{name}.png: {off:?} at scale {}", meta.scale);
        let (size, _) = read_mask_png(&out.join(format!("dynamic/{name}.png"))).unwrap();
        assert_eq!((size.width, size.height), (56, 42), "dynamic mask of the 56 x 42 network size");
        read_mask_png(&out.join(format!("sky/{name}.png"))).unwrap();
    }
}

/// Every render at an input time is the trainer's validation render of that view (the left panel of its
/// `frameNNN_camera0.png`), and the summary's input PSNR is that of the files.
fn check_renders(summary: &Summary, out: &Path, validation: &Path) {
    let mut psnrs = Vec::new();
    for render in summary.renders.iter().filter(|r| r.at_input) {
        let frame = (render.time_s * 10.0).round() as usize;
        let rendered = image::open(out.join(&render.file)).unwrap().to_rgb8();
        let panels = image::open(validation.join(format!("frame{frame:03}_camera0.png"))).unwrap().to_rgb8();
        assert_eq!(panels.dimensions(), (3 * rendered.width(), rendered.height()), "{}", render.file);
        let trainer = image::imageops::crop_imm(&panels, 0, 0, rendered.width(), rendered.height()).to_image();
        let differences: Vec<u8> =
            rendered.as_raw().iter().zip(trainer.as_raw()).map(|(a, b)| a.abs_diff(*b)).collect();
        let largest = differences.iter().copied().max().unwrap_or(0);
        let mean = differences.iter().map(|&d| f64::from(d)).sum::<f64>() / differences.len() as f64;
        eprintln!(
            "{}: against the trainer's render of frame {frame}, at most {largest}, mean {mean:.4} levels",
            render.file
        );
        assert!(
            largest <= MAX_LEVELS && mean <= MEAN_LEVELS,
            "{}: up to {largest} levels, mean {mean:.3}",
            render.file
        );

        let (_, rgb) = read_rgb_png(&out.join(&render.file)).unwrap();
        let (_, input) = read_rgb_png(&out.join(format!("images/{frame:03}_0.png"))).unwrap();
        assert!(rgb.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)), "{}", render.file);
        let mse = rgb.iter().zip(&input).map(|(a, b)| ((a - b) as f64).powi(2)).sum::<f64>() / rgb.len() as f64;
        psnrs.push(-10.0 * mse.log10());
    }
    assert_eq!(psnrs.len(), FRAMES, "one PSNR per frame");
    let mean_psnr = psnrs.iter().sum::<f64>() / psnrs.len() as f64;
    let reported = summary.input_psnr_db.iter().sum::<f64>() / summary.input_psnr_db.len() as f64;
    assert!((mean_psnr - reported).abs() < 0.5, "summary says {reported:.2} dB, the files {mean_psnr:.2} dB");
}

fn write_safetensors(path: &Path, tensors: &[(&str, Vec<usize>)]) {
    let data: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(name, shape)| (name.to_string(), shape.clone(), vec![0u8; 4 * shape.iter().product::<usize>()]))
        .collect();
    let views: Vec<(String, safetensors::tensor::TensorView)> = data
        .iter()
        .map(|(name, shape, bytes)| {
            (name.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), bytes).unwrap())
        })
        .collect();
    safetensors::serialize_to_file(views, None, path).unwrap();
}

fn error_of(options: &ReconstructOptions) -> String {
    match reconstruct(options, &Device::flex()) {
        Ok(_) => panic!("{options:?} should fail"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_inputs_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let fixture_options = |checkpoint: &Path| {
        let mut options = ReconstructOptions::new(fixture(), checkpoint, &out);
        options.cameras = Some(vec![0]);
        options.frames = Some(0..2);
        options.width = Some(56);
        options.architecture = Some(Architecture::Preset(dggt_model::Preset::Tiny));
        options
    };
    let garbage = dir.path().join("garbage.pt");
    std::fs::write(&garbage, b"this is not a checkpoint").unwrap();

    // No images.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let error = error_of(&ReconstructOptions::new(&empty, &garbage, &out));
    assert!(error.contains("empty") && error.contains("no images"), "{error}");

    // Mixed sizes: the odd file is named with both sizes.
    let mixed = dir.path().join("mixed");
    std::fs::create_dir(&mixed).unwrap();
    image::RgbImage::new(64, 48).save(mixed.join("000.png")).unwrap();
    image::RgbImage::new(64, 48).save(mixed.join("001.png")).unwrap();
    image::RgbImage::new(60, 48).save(mixed.join("002.png")).unwrap();
    let error = error_of(&ReconstructOptions::new(&mixed, &garbage, &out));
    assert!(error.contains("002.png") && error.contains("60x48") && error.contains("64x48"), "{error}");

    // Cameras with different frame counts.
    let rig = dir.path().join("rig");
    for (camera, frames) in [("front", 3), ("left", 2)] {
        std::fs::create_dir_all(rig.join(camera)).unwrap();
        for f in 0..frames {
            image::RgbImage::new(64, 48).save(rig.join(camera).join(format!("{f}.png"))).unwrap();
        }
    }
    let error = error_of(&ReconstructOptions::new(&rig, &garbage, &out));
    assert!(error.contains("left") && error.contains("one image per frame"), "{error}");

    // Unreadable checkpoints: garbage, a missing file, a folder that is no checkpoint.
    let error = error_of(&fixture_options(&garbage));
    assert!(error.contains("garbage.pt"), "{error}");
    let error = error_of(&fixture_options(&dir.path().join("missing.safetensors")));
    assert!(error.contains("missing.safetensors") && error.contains("does not exist"), "{error}");
    let error = error_of(&fixture_options(&empty));
    assert!(error.contains("empty") && error.contains("model.json"), "{error}");

    // Wrong architecture: a tensor whose shape the tiny network does not have is named with both shapes.
    let wrong = dir.path().join("wide.safetensors");
    write_safetensors(&wrong, &[("aggregator.camera_token", vec![1, 2, 1, 1024])]);
    let error = error_of(&fixture_options(&wrong));
    assert!(error.contains("wide.safetensors") && error.contains("aggregator.camera_token"), "{error}");
    assert!(error.contains("1024") && error.contains("64"), "{error}");
    // A file none of whose tensors the network has.
    let foreign = dir.path().join("foreign.safetensors");
    write_safetensors(&foreign, &[("encoder.layer.0.weight", vec![4, 4])]);
    let error = error_of(&fixture_options(&foreign));
    assert!(error.contains("foreign.safetensors") && error.contains("no tensor"), "{error}");
    // A file with only part of the core (an aggregator tensor of the right shape, nothing else).
    let partial = dir.path().join("partial.safetensors");
    write_safetensors(&partial, &[("aggregator.camera_token", vec![1, 2, 1, 64])]);
    let error = error_of(&fixture_options(&partial));
    assert!(error.contains("partial.safetensors") && error.contains("camera_head"), "{error}");
    assert!(!out.join("summary.json").exists(), "nothing is written on failure");
}

#[test]
fn glob_patterns_choose_images_or_camera_folders() {
    use dggt_infer::InputSet;
    let dir = tempfile::tempdir().unwrap();
    for (camera, frames) in [("cam_front", 3), ("cam_left", 3), ("notes", 0)] {
        std::fs::create_dir_all(dir.path().join(camera)).unwrap();
        for f in 0..frames {
            image::RgbImage::new(32, 24).save(dir.path().join(camera).join(format!("{f:02}.png"))).unwrap();
        }
    }
    std::fs::write(dir.path().join("cam_front").join("readme.txt"), "not an image").unwrap();

    // Files: one camera, in name order, only images.
    let set = InputSet::open(&dir.path().join("cam_front/0[12].png"), None, None).unwrap();
    assert_eq!(set.kind, "image glob");
    assert_eq!(set.cameras, vec!["cam0".to_string()]);
    let names: Vec<_> = set.views.iter().map(|v| v.path.file_name().unwrap().to_str().unwrap().to_owned()).collect();
    assert_eq!(names, ["01.png", "02.png"]);

    // Folders: a camera each, frame-major views.
    let set = InputSet::open(&dir.path().join("cam_*"), Some(1..3), None).unwrap();
    assert_eq!(set.cameras, vec!["cam_front".to_string(), "cam_left".to_string()]);
    assert_eq!(set.views.len(), 4);
    assert_eq!((set.views[1].frame, set.views[1].camera), (1, 1));

    // Nothing matching is an error naming the pattern.
    let pattern = dir.path().join("*.jpg");
    let error = InputSet::open(&pattern, None, None).unwrap_err().to_string();
    assert!(error.contains("*.jpg") && error.contains("no images"), "{error}");
}
