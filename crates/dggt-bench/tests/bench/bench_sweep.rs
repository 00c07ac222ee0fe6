//! A bounded sweep through the library on the bundled fixture with a fresh tiny model at a tiny width: the CSV
//! has one line per configuration, the baseline matches the exact render exactly, a high culling threshold
//! keeps fewer Gaussians, skipped configurations carry their reason, and the plot decodes at its size. Also:
//! the split stages compute what the pipeline computes.

use std::path::PathBuf;

use burn::tensor::{Device, Tensor, TensorData};
use dggt_bench::knobs::{Culling, Knobs, Precision, Skips, SweepSpec, Varied};
use dggt_bench::plot::PNG_SIZE;
use dggt_bench::report::CSV_HEADER;
use dggt_bench::run::fresh_tiny_config;
use dggt_bench::{BenchOptions, RowOutcome, run_bench, stages, write_outputs};
use dggt_geom::{PinholeIntrinsics, PosedCamera, WorldFromCamera};
use dggt_infer::SkyChoice;
use dggt_refine::{Latent, Prompt, ReferenceView, RefinerSpec};
use dggt_scene::{AssemblySettings, InputView, MeansGradient, PixelGaussians, TargetView, render_target};
use dggt_scene::{DynamicMotion, Scene4d};

fn fixture() -> PathBuf {
    dggt_test_data::fixture("synth-s0")
}

fn values<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor.into_data().convert::<f32>().try_into_vec::<f32>().expect("f32 values")
}

#[test]
fn bounded_sweep_writes_table_and_plot() {
    let device = Device::flex();
    let mut options = BenchOptions::new(fixture());
    options.repeat = 1;
    options.warmup = 0;
    options.sweep = SweepSpec {
        baseline: Knobs {
            width: 42,
            input_frames: 3,
            culling: Culling::MinOpacity(dggt_scene::MIN_OPACITY),
            precision: Precision::F32,
            sky: SkyChoice::Render,
            skips: Skips::Nothing,
            motion: DynamicMotion::Velocity,
        },
        widths: vec![],
        // 40 frames exceed the fixture's 16 non-target frames: skipped with the reason.
        input_frames: vec![40],
        min_opacities: vec![0.5],
        precisions: vec![Precision::Bf16],
        sky: vec![],
        skips: vec![Skips::All],
        motions: vec![DynamicMotion::Instances],
        full_grid: false,
    };
    // The tiny random refiner of the parity vectors (plumbing only: its images mean nothing), in the
    // reference-view mode (each render attends to its camera's nearest input view).
    let refiner = dggt_test_data::parity("difix_tiny_s1");
    options.refine = Some(RefinerSpec {
        model_dir: refiner.join("base"),
        checkpoint: refiner.join("model_difix.pkl"),
        prompt: Prompt::Tokens(vec![5, 7, 9]),
        latent: Latent::PosteriorMean,
        reference: ReferenceView::NearestInput,
        precision: Default::default(),
    });
    let report = run_bench(&options, &device).expect("the sweep runs");
    for row in report.rows.iter().filter_map(RowOutcome::measured) {
        let refined = row.refined.expect("every measured row refined");
        assert!(refined.refine_ms > 0.0 && refined.vs_truth.psnr_db.is_finite(), "{refined:?}");
        assert_ne!(refined.vs_truth.psnr_db, row.vs_truth.psnr_db, "the refiner changed nothing");
    }
    let configurations = options.sweep.configurations();
    assert_eq!(report.rows.len(), configurations.len());
    assert!(!report.truth_meaningful, "a fresh model's ground-truth error is flagged as meaningless");

    let exact = report.rows[0].measured().expect("the exact reference is measured");
    assert_eq!(exact.configuration.varied, Varied::Reference);
    let baseline = report.rows[1].measured().expect("the baseline is measured");
    assert_eq!(baseline.configuration.varied, Varied::Baseline);
    assert_eq!(exact.vs_exact.psnr_db, f64::INFINITY);
    assert_eq!(baseline.vs_exact.psnr_db, f64::INFINITY, "culling at the rasteriser's own threshold is lossless");
    assert!((baseline.vs_exact.ssim - 1.0).abs() < 1e-12);
    assert!(baseline.gaussians_kept <= exact.gaussians_kept);
    assert!(baseline.vs_truth.psnr_db.is_finite());

    let culled = report
        .rows
        .iter()
        .filter_map(RowOutcome::measured)
        .find(|r| r.configuration.knobs.culling == Culling::MinOpacity(0.5))
        .expect("the 0.5 threshold is measured");
    assert!(
        culled.gaussians_kept < baseline.gaussians_kept,
        "threshold 0.5 keeps {} Gaussians per view, the baseline {}",
        culled.gaussians_kept,
        baseline.gaussians_kept
    );

    let skipping = report
        .rows
        .iter()
        .filter_map(RowOutcome::measured)
        .find(|r| r.configuration.varied == Varied::Skips)
        .expect("the skips row is measured");
    assert_eq!(skipping.configuration.knobs.skips, Skips::All);
    // The motion skip is lossless and the sky skip changes a colour by under 1/255 of the sky's.
    assert!(skipping.vs_exact.psnr_db > 48.0, "skipping changed the renders: {:?}", skipping.vs_exact);
    assert_eq!((baseline.skipped.motion_frames, baseline.skipped.sky_views), (0, 0), "the baseline skips nothing");

    let too_many = report
        .rows
        .iter()
        .find(|r| r.configuration().knobs.input_frames == 40)
        .expect("the 40-frame configuration has a row");
    match too_many {
        RowOutcome::Skipped { reason, .. } => assert!(reason.contains("non-target frames"), "{reason}"),
        RowOutcome::Measured(_) => panic!("40 input frames cannot be measured on a 20-frame scene"),
    }
    let bf16 = report
        .rows
        .iter()
        .find(|r| r.configuration().knobs.precision == Precision::Bf16)
        .expect("the bf16 configuration has a row");
    // The device's declared types decide: a device that declares bf16 measures the row, one that does not
    // skips it with the reason in the notes.
    let declares_bf16 = device.supports_dtype(Precision::Bf16.dtype());
    match (bf16, declares_bf16) {
        (RowOutcome::Measured(row), true) => assert!(row.vs_exact.psnr_db > 10.0, "bf16 renders: {:?}", row.vs_exact),
        (RowOutcome::Skipped { reason, .. }, false) => {
            assert!(reason.contains("does not support bf16"), "{reason}");
            assert!(report.notes.iter().any(|n| n.contains("bf16") && n.contains(reason.as_str())));
        }
        (RowOutcome::Measured(_), false) => panic!("bf16 was measured on a device that does not declare it"),
        (RowOutcome::Skipped { reason, .. }, true) => {
            panic!("the device declares bf16 but the row was skipped: {reason}")
        }
    }
    assert!(report.notes.iter().any(|n| n.contains("refinement: every row's target renders also refined")));

    let out = tempfile::tempdir().expect("a temporary folder");
    let files = write_outputs(&report, out.path()).expect("the outputs are written");
    let csv = std::fs::read_to_string(&files.csv).expect("bench.csv");
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], CSV_HEADER);
    assert_eq!(lines.len(), 1 + configurations.len());
    let columns = CSV_HEADER.split(',').count();
    for line in &lines[1..] {
        // No field of these rows holds a quoted comma except a skip reason, which is last.
        let status_start = line.match_indices(',').nth(columns - 2).map(|(i, _)| i).expect("all columns");
        assert!(line[status_start + 1..].starts_with("measured") || line[status_start + 1..].contains("skipped: "));
    }
    assert!(lines[2].contains(",inf,"), "the baseline's PSNR vs exact is written as inf: {}", lines[2]);
    assert!(lines.iter().any(|l| l.contains("skipped: 40 input frames requested")));

    let png = image::open(&files.png).expect("bench.png decodes");
    assert_eq!((png.width(), png.height()), PNG_SIZE);
    let svg = std::fs::read_to_string(&files.svg).expect("bench.svg");
    assert!(svg.starts_with("<svg") && svg.contains("exact") && svg.trim_end().ends_with("</svg>"));
    let notes = std::fs::read_to_string(&files.notes).expect("bench-notes.txt");
    assert!(notes.contains("meaningless"));
}

#[test]
fn split_stages_compute_what_the_pipeline_computes() {
    let device = Device::flex();
    let model = dggt_infer::fresh_model(&fresh_tiny_config(), None, 7, &device).expect("a fresh tiny model");
    let (frames, height, width) = (2, 28, 42);
    let pixels: Vec<f32> = (0..frames * 3 * height * width).map(|i| ((i * 37 % 101) as f32) / 100.0).collect();
    let images = Tensor::<5>::from_data(TensorData::new(pixels, [1, frames, 3, height, width]), &device);

    let pipeline = dggt_infer::forward_chunked(&model, images.clone(), 1, dggt_infer::MotionPath::Always)
        .expect("pipeline forward");
    let aggregator = stages::backbone(&model, images.clone()).expect("backbone");
    let split = stages::heads(&model, aggregator, images.clone(), 1, dggt_infer::MotionPath::Always).expect("heads");
    assert_eq!(values(split.pose_encoding()), values(pipeline.pose_encoding()));
    assert_eq!(values(split.depth.clone()), values(pipeline.depth.clone()));
    assert_eq!(
        values(split.dynamic_logit.clone().expect("dynamic")),
        values(pipeline.dynamic_logit.clone().expect("dynamic"))
    );
    let (a, b) = (split.gaussians.as_ref().expect("maps"), pipeline.gaussians.as_ref().expect("maps"));
    assert_eq!(values(a.rgb.clone()), values(b.rgb.clone()));
    assert_eq!(values(a.opacity.clone()), values(b.opacity.clone()));
    assert_eq!(values(a.scale.clone()), values(b.scale.clone()));
    assert_eq!(values(a.lifespan.clone()), values(b.lifespan.clone()));

    let intrinsics = PinholeIntrinsics::new(40.0, 40.0, 21.0, 14.0).expect("intrinsics");
    let moved = WorldFromCamera::from_rows_3x4([[1.0, 0.0, 0.0, 0.1], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
        .expect("a pose");
    let views: Vec<InputView> = [WorldFromCamera::IDENTITY, moved]
        .iter()
        .enumerate()
        .map(|(i, &pose)| InputView {
            rig_camera: 0,
            time: i as f64 * 0.25,
            camera: PosedCamera { world_from_camera: pose, intrinsics },
        })
        .collect();
    let gaussians = PixelGaussians::new(
        a,
        split.depth.clone(),
        split.dynamic_logit.clone(),
        views.clone(),
        MeansGradient::Detached,
        model.unproject_at,
    )
    .expect("pixel Gaussians");
    let sky_model = model.sky_model.as_ref().expect("the tiny model has a sky");
    let cameras: Vec<_> = views.iter().map(|v| (v.camera.world_from_camera.inverse(), v.camera.intrinsics)).collect();
    let sky = sky_model.gaussians(images.reshape([frames, 3, height, width]), &cameras);
    let target = TargetView { rig_camera: 0, time: 0.1, camera: views[0].camera };
    for settings in [AssemblySettings::default(), AssemblySettings::exact()] {
        let expected = render_target(&gaussians, Some(&sky), &target, &settings).expect("pipeline render");
        let scene = Scene4d { pixels: gaussians.clone(), sky: Some(sky.clone()), assembly: settings };
        let assembled = scene.assemble(&target).expect("assembly");
        let ours = stages::rasterise(&scene, &assembled, &target).expect("raster");
        assert_eq!(ours.rgb, values(expected.rgb));
    }
}
