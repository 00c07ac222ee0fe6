//! The `dggt` command line as a newcomer uses it.

use std::process::{Command, Output};

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn fixture() -> String {
    dggt_test_data::fixture("synth-s0").display().to_string()
}

#[test]
fn inspect_summarises_the_fixture() {
    let out = dggt(&["inspect", &fixture(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["frames"], 20);
    assert_eq!(summary["cameras"].as_array().unwrap().len(), 3);
    assert_eq!(summary["cameras"][1]["name"], "FRONT_LEFT");
    assert_eq!(summary["cameras"][0]["width"], 160);
    for key in ["sky_masks", "dynamic_masks", "fine_dynamic_masks", "depth_flows"] {
        assert_eq!(summary[key], true, "{key}");
    }
    assert_eq!(summary["scene_flow"], "synthetic", "the generated scene's flow is exact");
    let length = summary["trajectory_length_m"].as_f64().unwrap();
    assert!((10.0..25.0).contains(&length), "{length}");

    let text = dggt(&["inspect", &fixture(), "--frames", "5..10", "--cameras", "0"]);
    assert!(text.status.success());
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(stdout.contains("frames     5 (indices 5..=9"), "{stdout}");
    assert!(stdout.contains("FRONT") && !stdout.contains("FRONT_LEFT"), "{stdout}");
    assert!(stdout.contains("flow       exact, from the generated scene"), "{stdout}");
}

#[test]
fn inspect_reports_bad_input_clearly() {
    let out = dggt(&["inspect", "/no/such/scene"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/no/such/scene"));
    let out = dggt(&["inspect", &fixture(), "--frames", "10..5"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("empty range"));
    let out = dggt(&["inspect", &fixture(), "--cameras", "4"]);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("intrinsics/4.txt"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn synth_refuses_to_overwrite_and_validates() {
    let out = dggt(&["synth", "--out", &fixture()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("not empty"));
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("bad");
    let out = dggt(&["synth", "--out", target.to_str().unwrap(), "--cameras", "4"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cameras"));
}

/// `--steps 0` is refused as the flag's error (not the configuration file's); `run.steps = 0` in a file names
/// the file and the key.
#[test]
fn train_refuses_zero_steps_naming_where_the_zero_comes_from() {
    let config = format!("{}/configs/tiny-overfit.toml", env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let flag = dggt(&["train", "--config", &config, "--steps", "0", "--out", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&flag.stderr);
    assert!(!flag.status.success());
    assert!(stderr.contains("--steps") && stderr.contains("'0'") && !stderr.contains("tiny-overfit.toml"), "{stderr}");
    assert!(!out.exists(), "a refused run wrote {}", out.display());

    let text = with_setting(&std::fs::read_to_string(&config).unwrap(), "steps", "0");
    let file = dir.path().join("zero.toml");
    std::fs::write(&file, text).unwrap();
    let zero = dggt(&["train", "--config", file.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&zero.stderr);
    assert!(!zero.status.success());
    assert!(stderr.contains("zero.toml") && stderr.contains("run.steps: must be at least 1"), "{stderr}");
}

/// `text` (a TOML file) with the one line setting `key` set to `value` instead.
fn with_setting(text: &str, key: &str, value: &str) -> String {
    let prefix = format!("{key} = ");
    assert_eq!(text.lines().filter(|l| l.starts_with(&prefix)).count(), 1, "one line sets {key}");
    text.lines().map(|l| if l.starts_with(&prefix) { format!("{prefix}{value}\n") } else { format!("{l}\n") }).collect()
}

/// The stderr of a run of `dggt args` that must fail.
fn refused(args: &[&str]) -> String {
    let out = dggt(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "dggt {args:?} succeeded:\n{stderr}");
    stderr
}

/// A failed command says what went wrong in words: no backtrace, even with `RUST_BACKTRACE=1` in the
/// environment (as it often is, for panics), and no colour codes in a log that is not written to a terminal;
/// `RUST_LIB_BACKTRACE=1` asks for the backtrace.
#[test]
fn errors_are_words_without_backtraces_or_colour_codes() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, out) = (fixture(), dir.path().join("out"));
    let args =
        ["reconstruct", "--images", scene.as_str(), "--checkpoint", "/no/such/run", "--out", out.to_str().unwrap()];
    let run = |variable: &str| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_dggt"));
        command.args(args).env_remove("NO_COLOR").env_remove("RUST_LIB_BACKTRACE").env("RUST_BACKTRACE", "1");
        let output = command.env(variable, "1").output().expect("the dggt binary runs");
        assert!(!output.status.success());
        String::from_utf8_lossy(&output.stderr).into_owned()
    };
    let stderr = run("RUST_BACKTRACE");
    assert!(stderr.contains("reconstructing") && stderr.contains("/no/such/run"), "{stderr}");
    assert!(!stderr.contains('\x1b'), "colour codes in a log written to a pipe:\n{stderr:?}");
    assert!(!stderr.to_lowercase().contains("backtrace") && stderr.lines().count() < 10, "{stderr}");
    assert!(run("RUST_LIB_BACKTRACE").contains("Stack backtrace:"));
}

/// `--every` and `--times` past the input frames' time window, and `--frames` past the scene's frames, are
/// refused before any work (here before the checkpoint is even opened), naming the flag, the value and the
/// valid range; an evaluation's stride that leaves one input, and a scene given twice, likewise.
#[test]
fn time_and_frame_arguments_past_the_scene_are_refused_naming_the_valid_range() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let (scene, out) = (fixture(), out.to_str().unwrap().to_string());
    let reconstruct = |extra: &[&str]| {
        let args = ["reconstruct", "--images", scene.as_str(), "--checkpoint", "/no/such/run", "--out", out.as_str()];
        refused(&[&args[..], extra].concat())
    };
    let past = reconstruct(&["--frames", "0..1000"]);
    assert!(past.contains("window 0..1000") && past.contains("the scene's 20 frames (0..=19)"), "{past}");
    assert!(!past.contains("ego_pose"), "{past}");
    let every = reconstruct(&["--frames", "0..2", "--every", "100000"]);
    assert!(every.contains("--every: 100000 is outside 1..=100"), "{every}");
    let times = reconstruct(&["--frames", "0..2", "--times", "1e9"]);
    assert!(times.contains("--times: 1000000000 s lies outside") && times.contains("0.000..=0.100"), "{times}");

    let eval = |extra: &[&str]| {
        let args = ["eval", "--scene", scene.as_str(), "--checkpoint", "/no/such/run", "--out", out.as_str()];
        refused(&[&args[..], extra].concat())
    };
    let stride = eval(&["--protocol", "interpolation", "--every", "30"]);
    assert!(
        stride.contains("--every: 30 leaves one input in the window 0..20") && stride.contains("1..=19"),
        "{stride}"
    );
    let twice = eval(&["--scene", format!("{scene}/.").as_str()]);
    assert!(twice.contains("--scene") && twice.contains("is given twice"), "{twice}");
    assert!(!std::path::Path::new(&out).exists(), "a refused command wrote {out}");
}

/// An output that could outgrow `--max-output-gb` is refused before anything is written, with the estimate
/// and the flag that raises the bound.
#[test]
fn synth_refuses_an_output_over_the_bound() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big");
    let args = ["synth", "--out", out.to_str().unwrap(), "--frames", "1000", "--width", "8192", "--height", "8192"];
    let stderr = refused(&args);
    assert!(stderr.contains("1000 frames x 3 cameras at 8192x8192") && stderr.contains("over the bound of 10.00 GB"));
    assert!(stderr.contains("--max-output-gb") && !out.exists(), "{stderr}");
    let small = refused(&["synth", "--out", out.to_str().unwrap(), "--max-output-gb", "0.0001"]);
    assert!(small.contains("over the bound of 0.00 GB"), "{small}");
}

/// A command writing one file the user names never replaces an existing one without `--overwrite`.
#[test]
fn single_file_outputs_are_not_replaced_without_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let existing = dir.path().join("kept.txt");
    std::fs::write(&existing, "the user's").unwrap();
    let file = existing.to_str().unwrap();
    let commands: [&[&str]; 3] = [
        &["refine", "convert", "--checkpoint", "/no/such/model_difix.pkl", "--out", file],
        &["stress", "--json", file],
        &["bench", "table", "--ours", "/no/such/compute.json", "--out", file],
    ];
    for args in commands {
        let stderr = refused(args);
        assert!(stderr.contains(&format!("{file} exists")) && stderr.contains("--overwrite"), "{args:?}: {stderr}");
        assert_eq!(std::fs::read_to_string(&existing).unwrap(), "the user's");
    }
    let replaced =
        refused(&["refine", "convert", "--checkpoint", "/no/such/model_difix.pkl", "--out", file, "--overwrite"]);
    assert!(replaced.contains("/no/such/model_difix.pkl"), "{replaced}");
}

/// Another path a command names, an output (`--rerun`) or an input, that is its `--out` folder or lies in it is
/// refused before any work (here before the checkpoint is opened), naming both; `--overwrite` removes nothing.
#[test]
fn paths_in_the_output_folder_are_refused_naming_both_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("recon");
    std::fs::create_dir_all(out.join("inputs")).unwrap();
    std::fs::write(out.join("summary.json"), "an earlier reconstruction's").unwrap();
    let (scene, out_text) = (fixture(), out.display().to_string());
    let reconstruct = ["reconstruct", "--checkpoint", "/no/such/run", "--out", out_text.as_str(), "--overwrite"];
    for rerun in [out.join("summary.json"), out.clone(), out.join("renders/../recording.rrd")] {
        let rerun = rerun.display().to_string();
        let stderr = refused(&[&reconstruct[..], &["--images", scene.as_str(), "--rerun", rerun.as_str()]].concat());
        assert!(stderr.contains(&format!("--rerun {rerun} lies in")), "{stderr}");
        assert!(stderr.contains(&format!("--out {out_text}")) && !stderr.contains("/no/such/run"), "{stderr}");
    }
    let inputs = out.join("inputs").display().to_string();
    let stderr = refused(&[&reconstruct[..], &["--images", inputs.as_str()]].concat());
    assert!(stderr.contains(&format!("--images {inputs} lies in")), "{stderr}");
    let eval = ["eval", "--scene", inputs.as_str(), "--checkpoint", "/no/such/run", "--out", out_text.as_str()];
    let stderr = refused(&[&eval[..], &["--overwrite"]].concat());
    assert!(stderr.contains(&format!("--scene {inputs} lies in")), "{stderr}");
    let saved = out.join("scene.safetensors").display().to_string();
    let stderr = refused(&["edit", "--scene", saved.as_str(), "--remove", "0", "--out", out_text.as_str()]);
    assert!(stderr.contains(&format!("--scene {saved} lies in")), "{stderr}");
    assert!(out.join("inputs").is_dir(), "an input in the output folder was removed");
    assert_eq!(std::fs::read_to_string(out.join("summary.json")).unwrap(), "an earlier reconstruction's");
}

/// An output another command holds (its lock beside the folder names a running process: this test's) is refused
/// at once, naming that command, and nothing is written into it.
#[test]
fn an_output_another_command_holds_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let lock = dir.path().join(".out.dggt-lock");
    std::fs::write(&lock, format!("{}\ndggt reconstruct\n", std::process::id())).unwrap();
    let (scene, out_text) = (fixture(), out.display().to_string());
    let config = format!("{}/configs/tiny-overfit.toml", env!("CARGO_MANIFEST_DIR"));
    let commands: [&[&str]; 3] = [
        &["reconstruct", "--images", scene.as_str(), "--checkpoint", "/no/such/run", "--out", out_text.as_str()],
        &["eval", "--scene", scene.as_str(), "--checkpoint", "/no/such/run", "--out", out_text.as_str()],
        &["train", "--config", config.as_str(), "--out", out_text.as_str(), "--dry-run"],
    ];
    for args in commands {
        let stderr = refused(args);
        assert!(stderr.contains(&format!("{out_text} is in use by `dggt reconstruct`")), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} wrote into a held output");
    }
    assert!(lock.is_file(), "another command's lock is left alone");
}

/// A sampler window too short for its inputs is a configuration error at `--dry-run`, not a run whose every
/// sample fails to load.
#[test]
fn train_dry_run_refuses_a_window_shorter_than_its_inputs() {
    let config = format!("{}/configs/tiny-overfit.toml", env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let text = with_setting(&std::fs::read_to_string(&config).unwrap(), "window", "3");
    let file = dir.path().join("short-window.toml");
    std::fs::write(&file, text).unwrap();
    let out = dir.path().join("run");
    let stderr = refused(&["train", "--config", file.to_str().unwrap(), "--dry-run", "--out", out.to_str().unwrap()]);
    let max_inputs = dggt_train::TrainConfig::load(std::path::Path::new(&config)).unwrap().sampler.max_inputs;
    let expected = format!("a window of 3 frames cannot hold max_inputs = {max_inputs}");
    assert!(stderr.contains("short-window.toml") && stderr.contains(&expected), "{stderr}");
}

#[test]
fn devices_checks_the_default_cpu_backend() {
    let out = dggt(&["devices", "--device", "cpu"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stdout));
    assert!(String::from_utf8_lossy(&out.stdout).contains("Cpu: ok"));
}

/// The GPU comparison's suite, at the reduced size on the CPU: every workload yields a figure, the table is
/// written, and `bench table` merges our records with a reference's and prints the ratio.
#[test]
fn bench_compute_runs_every_workload_at_reduced_size() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("compute");
    let run = dggt(&[
        "bench",
        "compute",
        "--scale",
        "reduced",
        "--device",
        "cpu",
        "--repeat",
        "2",
        "--warmup",
        "0",
        "--longest-budget-s",
        "60",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("compute.json")).unwrap()).unwrap();
    let records = file["records"].as_array().unwrap();
    let keys: Vec<&str> = records.iter().map(|r| r["key"].as_str().unwrap()).collect();
    for key in [
        "forward/2/f32",
        "forward/4/f32",
        "train-step/2+4/f32",
        "raster/20000x2/forward",
        "raster/20000x2/forward+backward",
    ] {
        let record = records.iter().find(|r| r["key"] == key).unwrap_or_else(|| panic!("no {key} in {keys:?}"));
        let ms = record["median_ms"].as_f64().unwrap_or_else(|| panic!("{key} has no time: {record}"));
        assert!(ms.is_finite() && ms > 0.0, "{key}: {ms}");
        assert_eq!(record["runs_ms"].as_array().unwrap().len(), 2, "{key}");
        // Without untimed runs, the first run (the one that compiles kernels) is the first timed one.
        assert_eq!(record["first_run_ms"], record["runs_ms"][0], "{key}");
    }
    let longest = records.iter().find(|r| r["key"] == "longest/bf16").expect("a longest-sequence record");
    // The CPU backend may not compute in bf16; then the record says why instead of a figure.
    match longest["frames"].as_u64() {
        Some(frames) => assert!((2..=8).contains(&frames), "{longest}"),
        None => assert!(longest["error"].as_str().is_some_and(|e| e.contains("bf16")), "{longest}"),
    }
    assert!(std::fs::read_to_string(out.join("compute.md")).unwrap().contains("| `forward/2/f32` |"));

    let reference = dir.path().join("reference.json");
    let forward_2 = records.iter().find(|r| r["key"] == "forward/2/f32").unwrap();
    let doubled = forward_2["median_ms"].as_f64().unwrap() * 2.0;
    std::fs::write(
        &reference,
        serde_json::json!({"implementation": "reference", "device": "CPU", "records": [
            {"key": "forward/2/f32", "impl": "release", "median_ms": doubled}
        ]})
        .to_string(),
    )
    .unwrap();
    let table = dggt(&[
        "bench",
        "table",
        "--ours",
        out.join("compute.json").to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
    ]);
    assert!(table.status.success(), "{}", String::from_utf8_lossy(&table.stderr));
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(text.contains("(release)") && text.contains("| 2.00x |"), "{text}");
}

/// `scripts/gpu-bench.sh` at the reduced scale: every part of ours and of the baseline build writes its records,
/// and the table shows ours beside the baseline with the gain, so that a GPU run is one prepared command. The
/// test's binary stands in for both builds, on the CPU backend (on Mesa's software Vulkan driver autotune alone
/// takes minutes).
#[test]
fn gpu_bench_script_measures_every_part_at_reduced_scale() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gpu");
    let binary = env!("CARGO_BIN_EXE_dggt");
    let script = format!("{}/scripts/gpu-bench.sh", env!("CARGO_MANIFEST_DIR"));
    let run = Command::new("bash")
        .args([&script, out.to_str().unwrap(), "--scale", "reduced", "--device", "cpu"])
        .args(["--dggt", binary, "--baseline-dggt", binary])
        .args(["--no-reference", "--budget-s", "900"])
        .output()
        .expect("bash runs the script");
    let log = format!("{}\n{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert!(run.status.success(), "{log}");
    let parts = std::fs::read_to_string(out.join("parts.txt")).unwrap();
    for part in ["ours-raster", "ours-forward", "ours-train-step", "ours-flow-head", "ours-longest", "baseline"] {
        assert!(parts.contains(&format!("== {part}: exit 0")), "{part} did not finish: {parts}\n{log}");
    }
    let table = std::fs::read_to_string(out.join("compute.md")).unwrap();
    assert!(table.contains("Baseline: dggt-rs, "), "{table}");
    let keys =
        ["raster/20000x2/forward+backward", "forward/4/f32", "train-step/2+4/f32", "flow-head/3x300/forward+backward"];
    for key in keys.into_iter().chain(["longest/f32"]) {
        let row = table.lines().find(|line| line.starts_with(&format!("| `{key}` |"))).unwrap_or_else(|| {
            panic!("no row for {key}:\n{table}");
        });
        assert!(!row.contains("failed"), "{row}");
    }
    let raster_row = table.lines().find(|line| line.starts_with("| `raster/20000x2/forward` |")).unwrap();
    let gain = raster_row.split('|').nth(5).unwrap().trim();
    assert!(gain.ends_with('x') && gain.trim_end_matches('x').parse::<f64>().is_ok(), "no gain: {raster_row}");

    // Again with the first run's baseline and a reference's records reused: neither is measured, both are in
    // the table.
    let reference = dir.path().join("reference.json");
    let record = serde_json::json!({"key": "forward/4/f32", "impl": "release", "median_ms": 1.0});
    std::fs::write(&reference, serde_json::json!({"implementation": "reference", "records": [record]}).to_string())
        .unwrap();
    let again = dir.path().join("again");
    let run = Command::new("bash")
        .args([&script, again.to_str().unwrap(), "--scale", "reduced", "--device", "cpu", "--dggt", binary])
        .args(["--reference-records", reference.to_str().unwrap()])
        .args(["--baseline-records", out.join("baseline/compute.json").to_str().unwrap(), "--budget-s", "900"])
        .output()
        .expect("bash runs the script");
    let log = format!("{}\n{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert!(run.status.success(), "{log}");
    let parts = std::fs::read_to_string(again.join("parts.txt")).unwrap();
    assert!(!parts.contains("baseline") && !parts.contains("reference"), "measured again: {parts}");
    let table = std::fs::read_to_string(again.join("compute.md")).unwrap();
    assert!(table.contains("Baseline: dggt-rs, ") && table.contains("1.0 ms (release)"), "{table}");
}

/// A saved scene of one view, 8x6 opaque grey Gaussians at depth 4, without a dynamic head.
fn tiny_saved_scene(dir: &std::path::Path) -> std::path::PathBuf {
    use burn::tensor::{Device, Tensor, TensorData};
    use dggt_geom::glam::{DQuat, DVec3};
    use dggt_geom::{PinholeIntrinsics, PixelConvention, PosedCamera, WorldFromCamera};
    let device = Device::flex();
    let (width, height) = (8, 6);
    let raw: Vec<f32> =
        (0..width * height).flat_map(|_| [0.0, 0.0, 0.0, 6.0, -1.0, -1.0, -1.0, 1.0, 0.0, 0.0, 0.0, 0.0]).collect();
    let maps = dggt_model::gaussian_maps::GaussianMaps::from_raw(Tensor::from_data(
        TensorData::new(raw, [1, 1, height, width, 12]),
        &device,
    ));
    let depth = Tensor::from_data(TensorData::new(vec![4.0f32; width * height], [1, 1, height, width]), &device);
    let camera = PosedCamera {
        world_from_camera: WorldFromCamera::from_rotation_translation(DQuat::IDENTITY, DVec3::ZERO).unwrap(),
        intrinsics: PinholeIntrinsics::new(8.0, 8.0, 4.0, 3.0).unwrap(),
    };
    let views = vec![dggt_scene::InputView { rig_camera: 0, time: 0.0, camera }];
    let pixels =
        dggt_scene::PixelGaussians::new(&maps, depth, None, views, Default::default(), PixelConvention::Centred)
            .unwrap();
    let scene = dggt_scene::Scene4d { pixels, sky: None, assembly: Default::default() };
    let file = dir.join("scene.safetensors");
    dggt_scene::save_scene(&scene, &file).unwrap();
    file
}

#[test]
fn edit_checks_every_edit_before_writing_and_never_mixes_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let scene = tiny_saved_scene(dir.path());
    let scene = scene.to_str().unwrap();
    let out = dir.path().join("edited");
    let out_arg = out.to_str().unwrap();
    assert!(refused(&["edit", "--scene", scene, "--out", out_arg]).contains("nothing to edit"));
    let message = refused(&["edit", "--scene", scene, "--remove", "0", "--out", out_arg]);
    assert!(message.contains("--remove 0") && message.contains("no moving objects"), "{message}");
    let message = refused(&["edit", "--scene", scene, "--move", "0:1,nan,0,0", "--out", out_arg]);
    assert!(message.contains("--move 0:1,nan,0,0") && message.contains("not a finite number"), "{message}");
    assert!(!out.exists(), "a refused edit writes nothing");

    let remove_box = ["edit", "--scene", scene, "--remove-box", "-1,-1,3,0,1,5", "--out", out_arg];
    let done = dggt(&remove_box);
    assert!(done.status.success(), "{}", String::from_utf8_lossy(&done.stderr));
    for file in [
        "edit.json",
        "renders/t0000_cam0.png",
        "before_after/t0000_cam0.png",
        "holes/t0000_cam0.png",
        "gaussians/t0000.ply",
    ] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("edit.json")).unwrap()).unwrap();
    assert!(
        summary["renders"][0]["hole_pixels"].as_u64().unwrap() > 0,
        "the box's left half uncovers nothing: {summary}"
    );
    assert!(refused(&remove_box).contains("not empty"));
    let again = dggt(&[&remove_box[..], &["--overwrite"]].concat());
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
}

/// The speed/accuracy sweep from the command line: one value per knob, a fresh tiny model, one timed run; the
/// table and its files are written. Without `--out` (or `--scene`) it says what it needs.
#[test]
fn bench_sweeps_the_fixture_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sweep");
    let (scene, out_arg) = (fixture(), out.to_str().unwrap().to_string());
    let knobs = [
        "--widths",
        "84",
        "--frame-counts",
        "4",
        "--frames",
        "4",
        "--min-opacities",
        "1/255",
        "--precisions",
        "f32",
        "--sky",
        "on",
        "--skips",
        "none",
        "--motions",
        "held",
        "--repeat",
        "1",
        "--warmup",
        "0",
    ];
    let mut args = vec!["bench", "--scene", &scene, "--out", &out_arg];
    args.extend(knobs);
    let run = dggt(&args);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let table = String::from_utf8_lossy(&run.stdout);
    assert!(table.contains("skip-none held"), "the swept motion has its row: {table}");
    let csv = std::fs::read_to_string(out.join("bench.csv")).expect("bench.csv");
    assert_eq!(csv.lines().count(), 4, "a header, the exact render, the baseline and the held row: {csv}");
    assert!(out.join("bench-notes.txt").is_file());

    let missing = dggt(&["bench", "--scene", &scene]);
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("needs --scene and --out"));
}

/// `dggt curves` draws the curves of runs (a run folder, or its metrics file) into one PNG, its folder created,
/// and prints each run's last and best validation PSNR; an existing PNG is replaced only with `--overwrite`.
#[test]
fn curves_draws_runs_into_one_png_and_replaces_it_only_with_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("seed-a");
    std::fs::create_dir(&run).unwrap();
    let mut metrics: Vec<String> = (0..40)
        .map(|step| {
            format!(r#"{{"kind":"train","step":{step},"loss":{},"target_psnr":20.0}}"#, 1.0 / (step + 1) as f64)
        })
        .collect();
    for (step, psnr) in [(10, 20.0), (20, 22.5), (30, 21.0)] {
        metrics.push(format!(r#"{{"kind":"validation","step":{step},"weights":"trained","psnr":{psnr},"ssim":0.5}}"#));
    }
    std::fs::write(run.join("metrics.jsonl"), metrics.join("\n")).unwrap();
    let (run_arg, out) = (run.to_str().unwrap(), dir.path().join("plots/curves.png"));
    let out_arg = out.to_str().unwrap();

    let drawn = dggt(&["curves", run_arg, "--out", out_arg]);
    assert!(drawn.status.success(), "{}", String::from_utf8_lossy(&drawn.stderr));
    let stdout = String::from_utf8_lossy(&drawn.stdout);
    assert!(stdout.contains(&format!("curves: {out_arg}")), "{stdout}");
    assert!(
        stdout.contains("seed-a: validation PSNR last 21.00 dB (step 30), best 22.50 dB at step 20"),
        "the run named by its folder: {stdout}"
    );
    assert_eq!(image::image_dimensions(&out).unwrap(), (1280, 560));
    let written = std::fs::read(&out).unwrap();

    let stderr = refused(&["curves", run_arg, "--out", out_arg]);
    assert!(stderr.contains(&format!("{out_arg} exists")) && stderr.contains("--overwrite"), "{stderr}");
    assert_eq!(std::fs::read(&out).unwrap(), written, "the refused command left the file as it was");

    let metrics_file = run.join("metrics.jsonl");
    let two = ["curves", run_arg, metrics_file.to_str().unwrap(), "--labels", "first,second", "--out", out_arg];
    let replaced = dggt(&[&two[..], &["--overwrite"]].concat());
    assert!(replaced.status.success(), "{}", String::from_utf8_lossy(&replaced.stderr));
    let stdout = String::from_utf8_lossy(&replaced.stdout);
    assert!(stdout.contains("first: validation PSNR") && stdout.contains("second: validation PSNR"), "{stdout}");
    assert_ne!(std::fs::read(&out).unwrap(), written, "two runs drawn over the one");

    let stderr = refused(&["curves", run_arg, "--labels", "a,b", "--out", out_arg, "--overwrite"]);
    assert!(stderr.contains("--labels gives 2 labels for 1 runs"), "{stderr}");
}
