//! `dggt eval` end to end on the bundled fixture (CPU): a tiny network trained one step (the run checks the
//! plumbing, not the quality), the paper protocol, every view and metric
//! checked in `eval.json` and `eval.md`; the reconstruction mode with LPIPS from the shared reference weights;
//! and the errors bad inputs give.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use dggt_eval::runner::NEAREST_INPUT;
use dggt_eval::{
    CropImages, EvalOptions, LpipsWeights, MOTION_HELD, MOTION_INSTANCES, MOTION_LEARNT, MOTION_VELOCITY, Protocol,
    evaluate,
};
use dggt_infer::{Architecture, CameraSource};
use dggt_refine::{Latent, Prompt, ReferenceView, RefinerSpec};
use dggt_scene::DynamicMotion;
use dggt_train::{RunOptions, Start, TrainConfig, Trainer};
use serde_json::Value;

fn repo() -> PathBuf {
    dggt_test_data::repo_root()
}

fn fixture() -> PathBuf {
    repo().join("data-fixtures/synth-s0")
}

fn parity_dir() -> PathBuf {
    dggt_test_data::Shared::Parity.dir()
}

/// Whether the tiny network predicts velocities, and how its dynamic Gaussians move.
#[derive(Clone, Copy, PartialEq)]
enum Motion {
    Held,
    GaussianVelocity,
    /// No velocities; the objects found among the dynamic pixels move along their trajectories.
    Instances,
    /// A flow head; the dynamic Gaussians move along its learnt flow.
    Learnt,
}

/// A tiny network after one training step on the fixture, saved as the trainer saves checkpoints.
fn tiny_checkpoint(run: &Path) {
    tiny_checkpoint_with(run, Motion::Held);
}

/// Trains the tiny network into `run` and returns its configuration.
fn tiny_checkpoint_with(run: &Path, motion: Motion) -> TrainConfig {
    let mut config = TrainConfig::load(&repo().join("configs/tiny-overfit.toml")).expect("tiny-overfit.toml loads");
    config.model.gaussian_velocity = motion == Motion::GaussianVelocity;
    match motion {
        Motion::Instances => config.render.dynamic_motion = DynamicMotion::Instances,
        Motion::Learnt => {
            config.model.flow_head = true;
            config.render.dynamic_motion = DynamicMotion::Learnt;
        }
        Motion::Held | Motion::GaussianVelocity => {}
    }
    config.data.scene = fixture();
    config.data.frames = None;
    config.data.preprocess.target_width = 56;
    config.sampler.min_inputs = 2;
    config.sampler.max_inputs = 2;
    config.sampler.window = 8;
    // One target per input and the learning rate these tests were written with: one step of it leaves a network
    // whose every view renders something to score.
    config.sampler.targets_per_input = 1;
    config.sampler.target_margin = 0;
    config.optim.lr = 4e-3;
    config.render.render_inputs = false;
    config.run.steps = 1;
    let mut trainer =
        Trainer::new(config.clone().unattended(run), vec![Device::flex()], Start::Fresh).expect("the trainer builds");
    let summary = trainer.run(RunOptions::default()).expect("one step trains");
    assert!(summary.checkpoint.is_some(), "the run ends with a checkpoint");
    config
}

fn number(value: &Value, key: &str) -> f64 {
    value[key].as_f64().unwrap_or_else(|| panic!("{key} is not a number in {value}"))
}

#[test]
fn paper_protocol_scores_every_view_of_the_fixture() {
    let run_dir = tempfile::tempdir().unwrap();
    tiny_checkpoint(run_dir.path());
    let out = tempfile::tempdir().unwrap();
    let mut options = EvalOptions::new(vec![fixture()], run_dir.path(), out.path());
    options.width = Some(84);
    let evaluated = evaluate(&options, &Device::flex()).unwrap();

    let report: Value = serde_json::from_slice(&std::fs::read(out.path().join("eval.json")).unwrap()).unwrap();
    assert_eq!(report["motion_source"], MOTION_HELD);
    assert_eq!(report["input_frames"], serde_json::json!([0, 5, 10, 15]));
    assert!(report["lpips_note"].as_str().unwrap().contains("no weights"));
    let scenes = report["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 1);
    assert_eq!(scenes[0]["network_size"], serde_json::json!([84, 56]));
    assert_eq!(scenes[0]["scene_flow"], "synthetic", "motion is scored against the generator's exact flow");
    let views = scenes[0]["views"].as_array().unwrap();
    // Every (frame, camera) of the window once: 4 input frames x 3 cameras reconstruction, 16 x 3 novel.
    let seen: BTreeSet<(u64, u64, String)> = views
        .iter()
        .map(|v| (v["frame"].as_u64().unwrap(), v["camera"].as_u64().unwrap(), v["split"].as_str().unwrap().into()))
        .collect();
    assert_eq!(seen.len(), 60);
    for frame in 0..20u64 {
        let split = if frame % 5 == 0 { "reconstruction" } else { "novel_view" };
        for camera in 0..3u64 {
            assert!(seen.contains(&(frame, camera, split.to_string())), "frame {frame} camera {camera} {split}");
        }
    }
    let mut motion_views = 0;
    for view in views {
        let psnr = number(view, "psnr");
        let ssim = number(view, "ssim");
        assert!(psnr.is_finite() && psnr > 0.0 && psnr < 100.0, "{view}");
        assert!((-1.0..=1.0).contains(&ssim), "{view}");
        assert!(view.get("lpips").is_none(), "LPIPS is absent without weights: {view}");
        // The fixture has lidar depth on every non-sky cell: every view has a D-RMSE.
        let d_rmse = number(view, "d_rmse");
        assert!(d_rmse.is_finite() && d_rmse >= 0.0, "{view}");
        assert!(view["depth_cells"].as_u64().unwrap() > 0, "{view}");
        if let Some(motion) = view.get("motion") {
            motion_views += 1;
            assert!(number(motion, "epe3d").is_finite() && number(motion, "epe3d") >= 0.0, "{motion}");
            for key in ["acc5", "acc10"] {
                assert!((0.0..=1.0).contains(&number(motion, key)), "{motion}");
            }
            assert!(number(motion, "acc5") <= number(motion, "acc10"), "{motion}");
            if let Some(angle) = motion["angle_error_rad"].as_f64() {
                // A held prediction is zero: every angle is pi/2.
                assert!((angle - std::f64::consts::FRAC_PI_2).abs() < 1e-9, "{motion}");
            }
        }
    }
    // The fixture's cars move faster than 1 m/s: motion is scored on every view.
    assert_eq!(motion_views, 60, "motion metrics on every view");
    // The moving cars' pixels are scored on their own where a view sees them, and only there.
    let moving: Vec<&Value> = views.iter().filter(|v| v["dynamic_pixels"].as_u64().unwrap() > 0).collect();
    assert!(!moving.is_empty(), "some view sees a moving car");
    for view in views {
        let seen = view["dynamic_pixels"].as_u64().unwrap() > 0;
        assert_eq!(view.get("dynamic_psnr").is_some(), seen, "{view}");
        if seen {
            let value = number(view, "dynamic_psnr");
            assert!(value.is_finite() && value > 0.0, "{view}");
        }
    }

    let overall = report["overall"].as_array().unwrap();
    let splits: Vec<&str> = overall.iter().map(|s| s["split"].as_str().unwrap()).collect();
    assert_eq!(splits, ["reconstruction", "novel_view"]);
    assert_eq!(scenes[0]["splits"][0]["count"], 12);
    assert_eq!(scenes[0]["splits"][1]["count"], 48);
    for summary in overall {
        for key in ["psnr", "ssim", "dynamic_psnr", "d_rmse", "epe3d", "acc5", "acc10", "angle_error_rad"] {
            assert!(number(summary, key).is_finite(), "{key} in {summary}");
        }
        assert!(summary["lpips"].is_null());
    }
    let stages: Vec<&str> = report["stages"].as_array().unwrap().iter().map(|s| s["stage"].as_str().unwrap()).collect();
    assert_eq!(stages, ["load", "forward", "assembly", "render", "metrics"]);

    let markdown = std::fs::read_to_string(out.path().join("eval.md")).unwrap();
    assert_eq!(markdown, evaluated.markdown());
    for heading in [
        "## reconstruction (input frames)",
        "## novel view synthesis",
        MOTION_HELD,
        "LPIPS: not computed",
        "true scene flow of synth-s0: exact",
        "### depth at depth edges (3x3 span > 1.3) and elsewhere; the median depth",
    ] {
        assert!(markdown.contains(heading), "{heading} missing from\n{markdown}");
    }
    // Each split's table and its depth parts, and the novel views' table against the nearest input copied.
    assert_eq!(markdown.matches("| synth-s0 |").count(), 5, "{markdown}");
    assert_eq!(markdown.matches("| **mean over scenes** |").count(), 5, "{markdown}");
    assert!(markdown.contains("| PSNR (dB) | PSNR copied |"), "{markdown}");
    for view in views {
        let at_input = view["split"] == "reconstruction";
        assert_eq!(view.get("nearest_input").is_none(), at_input, "the copy baseline at every non-input view: {view}");
        let abs_rel = number(view, "abs_rel");
        assert!(abs_rel.is_finite() && abs_rel >= 0.0, "{view}");
        let parts = &view["depth_parts"];
        for key in ["median_d_rmse", "median_abs_rel", "edge_fraction"] {
            let value = number(parts, key);
            assert!(value.is_finite() && value >= 0.0, "depth part {key} of {view}");
        }
        let (edges, elsewhere) = (parts["abs_rel_at_edges"].as_f64(), parts["abs_rel_elsewhere"].as_f64());
        let share = number(parts, "edge_fraction");
        // The parts average to the whole, weighted by their cells.
        let whole = share * edges.unwrap_or(0.0) + (1.0 - share) * elsewhere.unwrap_or(0.0);
        assert!((whole - abs_rel).abs() < 1e-9 * abs_rel.max(1.0), "parts {whole} against AbsRel {abs_rel}: {view}");
    }
    assert_export_poses_on_held_out_frames(run_dir.path());

    // The release's reconstruction mode on two frames of one camera, with LPIPS from the shared weights.
    let weights = parity_dir().join("metrics");
    let (linear, alexnet) =
        (weights.join("lpips_alex.safetensors"), weights.join("alexnet_features_torchvision_names.safetensors"));
    for file in [&linear, &alexnet] {
        assert!(
            file.is_file(),
            "{} not found: the LPIPS check needs the shared metrics vectors (set DGGT_PARITY_DIR to the shared \
             parity folder)",
            file.display()
        );
    }
    let out = tempfile::tempdir().unwrap();
    let mut options = EvalOptions::new(vec![fixture()], run_dir.path(), out.path());
    options.protocol = Protocol::reconstruction(6, 2, vec![1]);
    options.width = Some(56);
    options.lpips = Some(LpipsWeights { linear, alexnet });
    let report = evaluate(&options, &Device::flex()).unwrap();
    assert_eq!(report.scenes[0].views.len(), 2);
    assert_eq!(report.overall.len(), 1);
    for view in &report.scenes[0].views {
        assert_eq!((view.camera, view.camera_name.as_str()), (1, "FRONT_LEFT"));
        assert!(view.frame == 6 || view.frame == 7);
        let lpips = view.lpips.expect("LPIPS with weights");
        assert!(lpips.is_finite() && (0.0..2.0).contains(&lpips), "{lpips}");
    }
    assert!(report.lpips_note.is_none(), "{:?}", report.lpips_note);

    // The same views also scored after the tiny random refiner of the parity vectors (plumbing only): the
    // unrefined metrics are unchanged, the refined ones sit beside them in eval.json and eval.md.
    let refiner = parity_dir().join("difix_tiny_s1");
    options.refine = Some(RefinerSpec {
        model_dir: refiner.join("base"),
        checkpoint: refiner.join("model_difix.pkl"),
        prompt: Prompt::Tokens(vec![5, 7, 9]),
        latent: Latent::PosteriorMean,
        reference: ReferenceView::None,
        precision: Default::default(),
    });
    options.out = out.path().join("refined");
    let refined = evaluate(&options, &Device::flex()).unwrap();
    for (plain, view) in report.scenes[0].views.iter().zip(&refined.scenes[0].views) {
        assert_eq!((plain.psnr, plain.ssim, plain.lpips), (view.psnr, view.ssim, view.lpips));
        let scores = view.refined.as_ref().expect("refined scores");
        assert!(scores.psnr.is_finite() && scores.psnr != view.psnr, "{scores:?} vs {}", view.psnr);
        assert!((-1.0..=1.0).contains(&scores.ssim) && scores.lpips.is_some_and(|l| l.is_finite()), "{scores:?}");
    }
    let summary = refined.overall[0].refined.as_ref().expect("refined means");
    assert!(summary.psnr.is_some() && summary.ssim.is_some() && summary.lpips.is_some(), "{summary:?}");
    assert!(report.overall[0].refined.is_none());
    let markdown = std::fs::read_to_string(options.out.join("eval.md")).unwrap();
    assert!(markdown.contains("| PSNR (dB) | PSNR refined |") && markdown.contains("- refiner: "), "{markdown}");
    let json: Value = serde_json::from_slice(&std::fs::read(options.out.join("eval.json")).unwrap()).unwrap();
    assert!(json["scenes"][0]["views"][0]["refined"]["psnr"].is_number(), "{json}");

    // The reference-view mode: each render attends to its camera's nearest input view, which changes the
    // refined image (the UNet's self-attention spans both views) but not the unrefined scores.
    options.refine.as_mut().unwrap().reference = ReferenceView::NearestInput;
    options.out = out.path().join("refined-reference");
    let with_reference = evaluate(&options, &Device::flex()).unwrap();
    for (single, view) in refined.scenes[0].views.iter().zip(&with_reference.scenes[0].views) {
        assert_eq!((single.psnr, single.ssim), (view.psnr, view.ssim));
        let (single, joint) = (single.refined.as_ref().unwrap(), view.refined.as_ref().unwrap());
        assert!(joint.psnr.is_finite() && joint.psnr != single.psnr, "{joint:?} vs {single:?}");
    }
    let markdown = std::fs::read_to_string(options.out.join("eval.md")).unwrap();
    assert!(markdown.contains("reference view: nearest-input"), "{markdown}");
}

/// The export's poses and a list of scored frames: only the inputs and the listed frames are scored; an input
/// view's render is the same whichever frames are scored; a copied input scores exactly at its own frame.
fn assert_export_poses_on_held_out_frames(run: &Path) {
    let out = tempfile::tempdir().unwrap();
    let mut options = EvalOptions::new(vec![fixture()], run, out.path());
    options.width = Some(84);
    options.poses = CameraSource::GroundTruth;
    options.protocol = Protocol::interpolation(0, 9, 4, vec![0]);
    let all = evaluate(&options, &Device::flex()).unwrap();
    options.protocol.scored = Some(vec![2, 6]);
    options.out = out.path().join("held-out");
    let held_out = evaluate(&options, &Device::flex()).unwrap();
    let frames = |report: &dggt_eval::EvalReport| report.scenes[0].views.iter().map(|v| v.frame).collect::<Vec<_>>();
    assert_eq!(frames(&all), (0..9).collect::<Vec<_>>(), "every frame of the window scored");
    assert_eq!(frames(&held_out), vec![0, 2, 4, 6, 8], "the inputs and the held-out frames scored");
    for view in &held_out.scenes[0].views {
        let same = all.scenes[0].views.iter().find(|v| v.frame == view.frame).unwrap();
        assert_eq!((view.psnr, view.ssim, view.d_rmse), (same.psnr, same.ssim, same.d_rmse), "frame {}", view.frame);
        assert_eq!(view.nearest_input.is_some(), view.frame % 4 != 0, "frame {}", view.frame);
    }
    // Frame 1's nearest input is frame 0, frame 3's is frame 4: the copies differ from the renders.
    let copied = all.scenes[0].views[1].nearest_input.as_ref().unwrap();
    assert!(copied.psnr.is_finite() && copied.psnr != all.scenes[0].views[1].psnr, "{copied:?}");
    let markdown = held_out.markdown();
    assert!(markdown.contains("- cameras: the export's poses"), "{markdown}");

    // In passes of two inputs, [0, 4] and [4, 8]: every frame once, and the second pass's frames scored as an
    // evaluation of that pass alone scores them.
    options.protocol = Protocol { scored: None, inputs_per_pass: Some(2), ..Protocol::interpolation(0, 9, 4, vec![0]) };
    options.out = out.path().join("passes");
    let passes = evaluate(&options, &Device::flex()).unwrap();
    assert_eq!(frames(&passes), (0..9).collect::<Vec<_>>(), "each frame scored once, by its pass");
    assert_eq!(passes.scenes[0].input_frames, vec![0, 4, 8], "the window's inputs");
    options.protocol = Protocol::interpolation(4, 5, 4, vec![0]);
    options.out = out.path().join("second-pass");
    let second = evaluate(&options, &Device::flex()).unwrap();
    for view in &second.scenes[0].views {
        let joined = passes.scenes[0].views.iter().find(|v| v.frame == view.frame).unwrap();
        assert_eq!((joined.psnr, joined.d_rmse), (view.psnr, view.d_rmse), "frame {} as its pass alone", view.frame);
    }
    let first_pass_frame = passes.scenes[0].views.iter().find(|v| v.frame == 2).unwrap();
    let one_pass_frame = all.scenes[0].views.iter().find(|v| v.frame == 2).unwrap();
    assert_ne!(first_pass_frame.psnr, one_pass_frame.psnr, "frame 2 rendered from inputs 0 and 4 alone differs");
}

fn error_of(options: &EvalOptions) -> String {
    evaluate(options, &Device::flex()).map(|_| ()).unwrap_err().to_string()
}

#[test]
fn predicted_velocities_are_scored_at_the_input_views() {
    let run_dir = tempfile::tempdir().unwrap();
    tiny_checkpoint_with(run_dir.path(), Motion::GaussianVelocity);
    let out = tempfile::tempdir().unwrap();
    let mut options = EvalOptions::new(vec![fixture()], run_dir.path(), out.path());
    options.width = Some(84);
    options.crops = CropImages::Write;
    evaluate(&options, &Device::flex()).unwrap();

    let report: Value = serde_json::from_slice(&std::fs::read(out.path().join("eval.json")).unwrap()).unwrap();
    assert_eq!(report["motion_source"], MOTION_VELOCITY);
    let views = report["scenes"][0]["views"].as_array().unwrap();
    assert_sources_side_by_side(views, &["held", "velocity", "instances"], "velocity");
    assert_images_side_by_side(views, &out.path().join("crops/synth-s0"));
    let between = |v: &&Value| v["split"] == "novel_view" && v.get("motion_by_source").is_some();
    assert!(views.iter().any(|v| between(&v)), "no view between the inputs scored side by side");
    let (mut scored, mut unscored, mut moving) = (0, 0, 0);
    for view in views {
        match (view["split"].as_str().unwrap(), view.get("motion")) {
            ("reconstruction", Some(motion)) => {
                scored += 1;
                assert!(number(motion, "epe3d").is_finite() && number(motion, "epe3d") >= 0.0, "{motion}");
                // A prediction that is not zero: the angles are not pi/2 as a held one's are.
                if let Some(angle) = motion["angle_error_rad"].as_f64() {
                    assert!(angle.is_finite(), "{motion}");
                    moving += usize::from((angle - std::f64::consts::FRAC_PI_2).abs() > 1e-6);
                }
            }
            ("novel_view", Some(motion)) => {
                // Between the inputs the rendered flow is scored.
                unscored += usize::from(!number(motion, "epe3d").is_finite());
                scored += 1;
            }
            (split, motion) => panic!("{split} view with motion {motion:?}: {view}\n{}", report["scenes"][0]["notes"]),
        }
    }
    assert_eq!((scored, unscored), (60, 0), "every view scored, between the inputs through the rendered flow");
    assert!(moving > 0, "the predicted flow is not zero at the moving cells of any view");
    let overall = &report["overall"][0];
    assert_eq!(overall["split"], "reconstruction");
    assert!(number(overall, "epe3d").is_finite(), "{overall}");
}

/// Every view between the inputs with moving objects is drawn by every image source, the one the
/// reconstruction renders with (velocity, cross-faded as the configuration says) scoring as the render does;
/// the crops are one strip per such view, the truth and four sources wide; an input view has none.
fn assert_images_side_by_side(views: &[Value], crops: &Path) {
    let mut drawn = 0;
    let mut differ = 0;
    for view in views {
        let Some(listed) = view["dynamic_psnr_by_source"].as_array() else {
            let between_with_mask = view["split"] == "novel_view" && number(view, "dynamic_pixels") > 0.0;
            assert!(!between_with_mask, "a view between the inputs without its sources: {view}");
            continue;
        };
        assert_eq!(view["split"], "novel_view", "{view}");
        let psnr = |name: &str| number(listed.iter().find(|m| m["source"] == name).unwrap(), "dynamic_psnr");
        let names: Vec<&str> = listed.iter().map(|m| m["source"].as_str().unwrap()).collect();
        assert_eq!(names, ["held", "cross-fade", "velocity", "instances", NEAREST_INPUT], "{view}");
        assert_eq!(psnr("velocity"), number(view, "dynamic_psnr"), "{view}");
        differ += usize::from(psnr("held") != psnr("cross-fade"));
        let strip = crops.join(format!("f{:04}_c{}.png", number(view, "frame"), number(view, "camera")));
        let (size, _) =
            dggt_formats::images::read_rgb_png(&strip).unwrap_or_else(|e| panic!("{}: {e}", strip.display()));
        let tile = (size.width - 4 * 2) / 5;
        assert_eq!(size.width, 5 * tile + 4 * 2, "{}", strip.display());
        assert!(size.height >= 96, "{}", strip.display());
        drawn += 1;
    }
    let files = std::fs::read_dir(crops).unwrap().count();
    assert!(drawn > 0 && files == drawn, "{drawn} views drawn by every source, {files} crops");
    assert!(differ > 0, "held and cross-faded never differ");
}

/// Every scored input view lists `sources` in order, the rendered source's metrics equal to its `motion`; a view
/// between the inputs lists them only when each is scored there (the rendered one is, through its rendered flow).
fn assert_sources_side_by_side(views: &[Value], sources: &[&str], rendered: &str) {
    let (mut inputs, mut moving) = (0, 0);
    for view in views.iter().filter(|v| v.get("motion").is_some()) {
        let input = view["split"] == "reconstruction";
        let Some(listed) = view["motion_by_source"].as_array() else {
            assert!(!input, "an input view without sources: {view}");
            continue;
        };
        let names: Vec<&str> = listed.iter().map(|m| m["source"].as_str().unwrap()).collect();
        assert_eq!(names, sources, "{view}");
        let own = listed.iter().find(|m| m["source"] == rendered).unwrap();
        assert_eq!(own["epe3d"], view["motion"]["epe3d"], "{view}");
        let held = listed.iter().find(|m| m["source"] == "held").unwrap();
        moving += usize::from(number(held, "epe3d") > 0.0);
        inputs += usize::from(input);
    }
    assert!(inputs > 0 && moving > 0, "{inputs} input views scored side by side, {moving} with moving cells");
}

/// Trains the tiny network one step with `motion`, evaluates it with its training configuration (`--config`: the
/// render settings come from it) and returns the report, its `eval.json` and its `eval.md`.
fn evaluate_trained(motion: Motion) -> (dggt_eval::EvalReport, Value, String) {
    let run_dir = tempfile::tempdir().unwrap();
    let config = tiny_checkpoint_with(run_dir.path(), motion);
    let config_path = run_dir.path().join("train.toml");
    std::fs::write(&config_path, toml::to_string(&config).unwrap()).unwrap();
    let out = tempfile::tempdir().unwrap();
    let mut options = EvalOptions::new(vec![fixture()], run_dir.path(), out.path());
    options.width = Some(84);
    options.architecture = Some(Architecture::Config(config_path));
    let evaluated = evaluate(&options, &Device::flex()).unwrap();
    let report: Value = serde_json::from_slice(&std::fs::read(out.path().join("eval.json")).unwrap()).unwrap();
    let markdown = std::fs::read_to_string(out.path().join("eval.md")).unwrap();
    (evaluated, report, markdown)
}

#[test]
fn instance_trajectories_are_rendered_and_scored_beside_held() {
    let (evaluated, report, markdown) = evaluate_trained(Motion::Instances);
    assert_eq!(report["motion_source"], MOTION_INSTANCES);
    assert_sources_side_by_side(report["scenes"][0]["views"].as_array().unwrap(), &["held", "instances"], "instances");
    let overall = &evaluated.overall[0];
    let names: Vec<&str> = overall.motion_by_source.iter().map(|m| m.source.as_str()).collect();
    assert_eq!(names, ["held", "instances"]);
    assert!(markdown.contains("### motion by source") && markdown.contains("| instances |"), "{markdown}");
}

#[test]
fn the_learnt_flow_is_rendered_and_scored_beside_the_other_sources() {
    let (evaluated, report, markdown) = evaluate_trained(Motion::Learnt);
    assert_eq!(report["motion_source"], MOTION_LEARNT);
    let views = report["scenes"][0]["views"].as_array().unwrap();
    assert_sources_side_by_side(views, &["held", "instances", "learnt"], "learnt");
    let overall = evaluated.overall.iter().find(|s| !s.dynamic_psnr_by_source.is_empty()).expect("in-between views");
    let names: Vec<&str> = overall.dynamic_psnr_by_source.iter().map(|s| s.source.as_str()).collect();
    assert_eq!(names, ["held", "cross-fade", "instances", "learnt", NEAREST_INPUT]);
    assert!(markdown.contains("### moving objects between the inputs by source") && markdown.contains("| learnt |"));
}

#[test]
fn bad_inputs_give_errors_naming_them() {
    let out = tempfile::tempdir().unwrap();
    // The scenes are checked before the checkpoint is read, so none is needed here.
    let checkpoint = out.path().join("no-checkpoint");
    let options = |scenes: Vec<PathBuf>| EvalOptions::new(scenes, &checkpoint, out.path().join("eval"));

    let missing = out.path().join("no-such-scene");
    let message = error_of(&options(vec![fixture(), missing.clone()]));
    assert!(message.contains(&missing.display().to_string()) && message.contains("not found"), "{message}");

    let not_export = out.path().to_path_buf();
    let message = error_of(&options(vec![not_export]));
    assert!(message.contains("not a scene export"), "{message}");

    let mut few = options(vec![fixture()]);
    few.protocol.start = 10;
    let message = error_of(&few);
    assert!(message.contains("synth-s0") && message.contains("too few frames"), "{message}");
    assert!(message.contains("20 frames (0..=19)") && message.contains("10..=29"), "{message}");

    let mut camera = options(vec![fixture()]);
    camera.protocol.cameras = vec![0, 5];
    let message = error_of(&camera);
    assert!(message.contains("synth-s0") && message.contains("no camera 5"), "{message}");
    assert!(message.contains("[0, 1, 2]"), "{message}");

    let message = error_of(&options(vec![]));
    assert!(message.contains("--scene"), "{message}");

    // With good scenes the checkpoint is next.
    let message = error_of(&options(vec![fixture()]));
    assert!(message.contains("no-checkpoint") && message.contains("does not exist"), "{message}");
}

#[test]
fn exports_without_depth_maps_are_scored_against_their_projected_lidar() {
    let data = tempfile::tempdir().unwrap();
    let scene = data.path().join("nuscenes-000");
    let synth = dggt_synth::SynthConfig { seed: 60, frames: 20, cameras: 3, width: 64, height: 48 };
    dggt_synth::synthesize(&synth, &scene, dggt_data::ExportVariant::NuScenes, dggt_synth::Sweeps::Write).unwrap();
    std::fs::remove_dir_all(scene.join("depth_flows_4")).unwrap();
    let run_dir = tempfile::tempdir().unwrap();
    tiny_checkpoint(run_dir.path());
    let out = tempfile::tempdir().unwrap();
    let mut options = EvalOptions::new(vec![scene], run_dir.path(), out.path());
    options.width = Some(56);
    let report = evaluate(&options, &Device::flex()).unwrap();
    let scene = &report.scenes[0];
    assert_eq!(scene.views.len(), 60);
    for view in &scene.views {
        let d_rmse = view.d_rmse.unwrap_or_else(|| panic!("no D-RMSE: {:?}", view.depth_note));
        assert!(d_rmse.is_finite() && d_rmse >= 0.0 && view.depth_cells > 0, "{d_rmse} {}", view.depth_cells);
        assert!(view.motion.is_none(), "lidar carries no scene flow");
    }
    assert!(scene.notes.iter().any(|n| n.contains("projected lidar")), "{:?}", scene.notes);
}
