//! Rerun recordings read back with rerun's own Python SDK (`rerun-sdk` of the crate's version,
//! `tests/rerun_readback.py`) as a client would.
//!
//! - `dggt reconstruct --rerun`: a tiny network trained one step reconstructs three frames of the fixture's two
//!   cameras; the recording's entity paths, the splats at every rendered time, the cameras' poses and the time
//!   lines' values match `summary.json`, `cameras.json` and the PLY files.
//! - `dggt train --rerun` and `--rerun-connect`: a short run's scalars, validation scores, renders, cameras and
//!   splats on the `step` time line, written to a file and streamed to a viewer process (`rerun --save`, the
//!   pinned CLI in server mode); a viewer killed mid-run leaves the run's weights as an unwatched run's.

mod common;

use std::io::BufRead;
use std::net::{TcpListener, TcpStream};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use dggt_formats::cameras_json::read_cameras_json;
use dggt_formats::ply::read_ply;
use serde_json::Value;

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn succeeded(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    stdout
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// What `tests/rerun_readback.py` reads from `rrd`.
fn read_back(rrd: &Path) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/rerun_readback.py");
    let out = Command::new("python3").arg(&script).arg(rrd).output().expect(
        "python3 runs (the recording is read back with rerun's Python SDK: pip install rerun-sdk==0.36.3, as .ci/run does)",
    );
    assert!(
        out.status.success(),
        "reading the recording back failed (is rerun-sdk 0.36.3 installed? .ci/run installs it):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn splat_count(file: &Path) -> usize {
    read_ply(file).unwrap().to_cloud().unwrap().len()
}

#[test]
fn a_reconstruction_recording_reads_back_as_its_files_say() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let work = tempfile::tempdir().unwrap();
    let (run, out, rrd) = (work.path().join("run"), work.path().join("reconstruction"), work.path().join("scene.rrd"));
    let config = repo.join("configs/tiny-overfit.toml");
    succeeded(&dggt(&["train", "--config", path(&config), "--steps", "1", "--out", path(&run)]));
    let fixture = dggt_test_data::fixture("synth-s0");
    let reconstruct = [
        "reconstruct",
        "--images",
        path(&fixture),
        "--checkpoint",
        path(&run),
        "--cameras",
        "0,1",
        "--frames",
        "0..3",
        "--every",
        "2",
        "--width",
        "56",
        "--out",
        path(&out),
        "--rerun",
        path(&rrd),
    ];
    let text = succeeded(&dggt(&reconstruct));
    assert!(text.contains("recording:"), "{text}");
    let recording = read_back(&rrd);
    assert_eq!(recording["rerun_version"], "0.36.3");
    assert_eq!(recording["blueprints"], 1, "the recording carries its default layout");
    let entities = recording["entities"].as_object().unwrap();
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();

    // Every camera's views, the Gaussians and the summary are there.
    for camera in 0..2 {
        for part in ["", "/image", "/depth", "/dynamic", "/sky", "/render"] {
            let entity = format!("/world/camera_{camera}{part}");
            assert!(entities.contains_key(&entity), "{entity} missing: {:?}", entities.keys().collect::<Vec<_>>());
        }
    }
    for entity in ["/world", "/world/gaussians/static", "/world/gaussians/sky", "/summary"] {
        assert_eq!(entities[entity]["static"], true, "{entity}");
    }
    let statics = &entities["/world/gaussians/static"]["rows"][0]["GaussianSplats3D:centers"];
    assert_eq!(statics.as_u64().unwrap() as usize, splat_count(&out.join("gaussians/static.ply")));

    // The dynamic splats at every rendered time: the times of summary.json, the counts of the PLY files.
    let times: Vec<f64> = summary["times_s"].as_array().unwrap().iter().map(|t| t.as_f64().unwrap()).collect();
    assert_eq!(times.len(), 5, "frames 0..3 at two renders per interval");
    let dynamic = entities["/world/gaussians/dynamic"]["rows"].as_array().unwrap();
    assert_eq!(dynamic.len(), times.len());
    for (k, (row, time)) in dynamic.iter().zip(&times).enumerate() {
        assert_eq!(row["time_ns"].as_i64().unwrap(), (time * 1e9).round() as i64, "time {k}");
        let expected = splat_count(&out.join(format!("gaussians/dynamic_t{k:04}.ply")));
        assert_eq!(row["GaussianSplats3D:centers"].as_u64().unwrap() as usize, expected, "time {k}");
    }

    // Each camera's pose at its input times, and its frame numbers, as cameras.json has them.
    let (_, cameras) = read_cameras_json(&out.join("cameras.json")).unwrap();
    for camera in 0..2 {
        let records: Vec<_> = cameras.iter().filter(|c| c.camera == camera).collect();
        let rows = entities[&format!("/world/camera_{camera}")]["rows"].as_array().unwrap();
        let poses: Vec<&Value> = rows.iter().filter(|row| row.get("Transform3D:translation").is_some()).collect();
        assert_eq!(poses.len(), records.len(), "camera {camera}");
        for (row, record) in poses.iter().zip(&records) {
            assert_eq!(row["frame"].as_u64().unwrap() as usize, record.frame);
            assert_eq!(row["time_ns"].as_i64().unwrap(), (record.time_s * 1e9).round() as i64);
            let t = record.world_from_camera.translation();
            let q = record.world_from_camera.rotation();
            let got_t: Vec<f64> =
                row["Transform3D:translation"][0].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            let got_q: Vec<f64> =
                row["Transform3D:quaternion"][0].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            for (got, expected) in got_t.iter().zip(t.to_array()) {
                assert!((got - expected).abs() < 1e-5, "camera {camera} frame {}: {got_t:?} vs {t}", record.frame);
            }
            for (got, expected) in got_q.iter().zip([q.x, q.y, q.z, q.w]) {
                assert!((got - expected).abs() < 1e-5, "camera {camera} frame {}: {got_q:?} vs {q}", record.frame);
            }
        }
    }

    // The moving objects' boxes, one per appearance.
    for instance in summary["instances"].as_array().unwrap() {
        let entity = format!("/world/instances/{}", instance["id"]);
        let boxes = entities[&entity]["rows"].as_array().unwrap().len();
        assert_eq!(boxes, instance["appearances"].as_array().unwrap().len(), "{entity}");
    }

    // An existing recording is not replaced without --overwrite, and nothing is reconstructed first.
    let again = work.path().join("again");
    let refused = dggt(&[&reconstruct[..13], &["--out", path(&again), "--rerun", path(&rrd)]].concat());
    assert!(!refused.status.success() && String::from_utf8_lossy(&refused.stderr).contains("--rerun"));
    assert!(!again.exists(), "a refused recording starts no reconstruction");
}

/// The small overfit run of `steps` steps, validated every second step on frame 2 between inputs 0 and 4 (one
/// camera), at most 400 splats a snapshot, written to `dir/NAME.toml`.
fn watched_config(dir: &Path, name: &str, steps: u64) -> PathBuf {
    let mut config = common::small_config(&dir.join("unused"));
    config.run.steps = steps;
    config.run.validate_every = 2;
    config.data.validation.inputs = vec![0, 4];
    config.data.validation.targets = vec![2];
    config.viewer.max_splats = 400;
    common::write_config(dir.join(format!("{name}.toml")), &config)
}

fn train(config: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_dggt"));
    command.args(["train", "--config", path(config), "--out", path(out)]).args(extra);
    command
}

/// The `step` values of an entity's rows.
fn steps(entities: &serde_json::Map<String, Value>, entity: &str) -> Vec<u64> {
    let rows = entities.get(entity).unwrap_or_else(|| panic!("{entity} missing: {:?}", entities.keys()));
    rows["rows"].as_array().unwrap().iter().filter_map(|row| row["step"].as_u64()).collect()
}

/// The validation records of a run's `metrics.jsonl`: `(step, psnr)`.
fn validation_records(out: &Path) -> Vec<(u64, f64)> {
    let text = std::fs::read_to_string(out.join("metrics.jsonl")).unwrap();
    text.lines()
        .map(|line| serde_json::from_str::<Value>(line).unwrap())
        .filter(|record| record["kind"] == "validation")
        .map(|record| (record["step"].as_u64().unwrap(), record["psnr"].as_f64().unwrap()))
        .collect()
}

#[test]
fn a_training_recording_holds_each_step_and_validation_on_the_step_time_line() {
    let work = tempfile::tempdir().unwrap();
    let config = watched_config(work.path(), "watched", 4);
    let (out, rrd) = (work.path().join("run"), work.path().join("training.rrd"));
    let text = succeeded(&train(&config, &out, &["--rerun", path(&rrd)]).output().unwrap());
    assert!(
        text.contains(&format!("recording: {}", rrd.display())) && text.contains("4 steps, 2 validation passes"),
        "{text}"
    );
    let recording = read_back(&rrd);
    assert_eq!(recording["blueprints"], 1, "the recording carries its layout");
    let entities = recording["entities"].as_object().unwrap();

    // Every step's scalars, as metrics.jsonl numbers the steps.
    for entity in
        ["/train/loss", "/train/target_psnr", "/train/learning_rate", "/train/grad_norm", "/train/terms/rgb_l2"]
    {
        assert_eq!(steps(entities, entity), [0, 1, 2, 3], "{entity}");
    }
    // The validation scores are the run's own.
    let recorded: Vec<(u64, f64)> = entities["/validation/scores/psnr"]["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| (row["step"].as_u64().unwrap(), row["Scalars:scalars"][0].as_f64().unwrap()))
        .collect();
    let expected = validation_records(&out);
    assert_eq!(recorded.len(), 2);
    for ((step, psnr), (expected_step, expected_psnr)) in recorded.iter().zip(&expected) {
        assert_eq!(step, expected_step);
        assert!((psnr - expected_psnr).abs() < 1e-9, "step {step}: {psnr} vs {expected_psnr}");
    }
    // At each pass the target's render, truth, difference and depth, the inputs' cameras (predicted and the
    // export's) with their images, depth and dynamic masks, and the window's splats.
    for part in ["render", "truth", "difference", "depth"] {
        assert_eq!(steps(entities, &format!("/validation/f002_c0/{part}")), [2, 4], "{part}");
    }
    for view in ["f000_c0", "f004_c0"] {
        for entity in [format!("/world/predicted/{view}"), format!("/world/export/{view}")] {
            let rows = entities[&entity]["rows"].as_array().unwrap();
            let poses = rows.iter().filter(|row| row.get("Transform3D:translation").is_some()).count();
            assert_eq!(poses, 2, "{entity}");
        }
        assert_eq!(steps(entities, &format!("/world/predicted/{view}/image")), [2, 4], "{view}/image");
        for part in ["depth", "dynamic"] {
            assert_eq!(steps(entities, &format!("/validation/inputs/{view}/{part}")), [2, 4], "{view}/{part}");
        }
    }
    let export = &entities["/world/export/f000_c0"]["rows"].as_array().unwrap();
    let first = export.iter().find_map(|row| row.get("Transform3D:translation")).unwrap();
    let norm: f64 = first[0].as_array().unwrap().iter().map(|v| v.as_f64().unwrap().powi(2)).sum();
    assert!(norm < 1e-10, "the window's world is its first input camera's frame: {first}");
    for row in entities["/world/gaussians"]["rows"].as_array().unwrap() {
        let splats = row["GaussianSplats3D:centers"].as_u64().unwrap();
        assert!((1..=400).contains(&splats), "{splats} splats, at most [viewer] max_splats = 400");
    }

    // A recording is never replaced: an existing file is refused before any work.
    let again = work.path().join("again");
    let refused = train(&config, &again, &["--rerun", path(&rrd)]).output().unwrap();
    assert!(!refused.status.success() && String::from_utf8_lossy(&refused.stderr).contains("the file exists"));
    assert!(!again.exists(), "a refused recording starts no run");
}

/// A `rerun` viewer in server mode on a free port, saving what it receives to `save`.
struct ViewerProcess {
    child: Child,
    url: String,
}

impl ViewerProcess {
    fn start(save: &Path) -> Self {
        let port = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        // Its own process group: `rerun` may be a launcher (a pip entry point behind a shim) whose child serves.
        let mut command = Command::new("rerun");
        command.args(["--port", &port.to_string(), "--bind", "127.0.0.1", "--save", path(save)]).process_group(0);
        // SIGINT at its default, whatever this process inherited: a shell starts background jobs with SIGINT
        // ignored, children inherit that, and Python then leaves it ignored, so Ctrl-C would never reach the viewer.
        // SAFETY: `signal` is async-signal-safe, and the closure touches nothing else between fork and exec.
        unsafe {
            command.pre_exec(|| {
                libc::signal(libc::SIGINT, libc::SIG_DFL);
                Ok(())
            });
        }
        let child = command
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("the rerun CLI runs (pip install rerun-sdk==0.36.3, as .ci/run does)");
        let started = Instant::now();
        while TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(started.elapsed() < Duration::from_secs(60), "the viewer never listened on port {port}");
            std::thread::sleep(Duration::from_millis(50));
        }
        Self { child, url: format!("rerun+http://127.0.0.1:{port}/proxy") }
    }

    /// Sends `signal` to the viewer's whole process group.
    fn signal(&self, signal: libc::c_int) {
        let group = self.child.id() as libc::pid_t;
        // SAFETY: `kill` only sends a signal, to the group this test started.
        unsafe { libc::kill(-group, signal) };
    }

    /// Stops it as Ctrl-C would, letting it close its file.
    fn interrupt(mut self) {
        self.signal(libc::SIGINT);
        let started = Instant::now();
        while self.child.try_wait().unwrap().is_none() {
            assert!(started.elapsed() < Duration::from_secs(30), "the viewer did not stop on SIGINT");
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for ViewerProcess {
    /// Kills it (the whole group) as a crash would.
    fn drop(&mut self) {
        self.signal(libc::SIGKILL);
        self.child.wait().ok();
    }
}

/// The training records of a run's `metrics.jsonl` so far.
fn trained_steps(out: &Path) -> usize {
    let Ok(file) = std::fs::File::open(out.join("metrics.jsonl")) else { return 0 };
    std::io::BufReader::new(file)
        .lines()
        .map_while(Result::ok)
        .filter(|line| line.contains(r#""kind":"train""#))
        .count()
}

#[test]
fn a_run_streams_to_a_viewer_and_trains_on_unchanged_when_the_viewer_is_killed() {
    let work = tempfile::tempdir().unwrap();

    // Streamed to a viewer, which receives the run's entities.
    let received = work.path().join("received.rrd");
    let viewer = ViewerProcess::start(&received);
    let short = watched_config(work.path(), "short", 2);
    let text =
        succeeded(&train(&short, &work.path().join("streamed"), &["--rerun-connect", &viewer.url]).output().unwrap());
    assert!(text.contains("recording: the viewer at") && !text.contains("stopped early"), "{text}");
    viewer.interrupt();
    let entities = read_back(&received)["entities"].as_object().unwrap().clone();
    assert_eq!(steps(&entities, "/train/loss"), [0, 1]);
    assert_eq!(steps(&entities, "/validation/f002_c0/render"), [2]);
    assert!(entities.contains_key("/world/gaussians") && entities.contains_key("/world/predicted/f004_c0"));

    // The viewer killed after the first validation pass of an 8-step run: the run goes on and ends with the
    // weights of the same run unwatched.
    let config = watched_config(work.path(), "long", 8);
    let unwatched = work.path().join("unwatched");
    succeeded(&train(&config, &unwatched, &[]).output().unwrap());
    let viewer = ViewerProcess::start(&work.path().join("killed.rrd"));
    let watched = work.path().join("watched");
    let mut run = train(&config, &watched, &["--rerun-connect", &viewer.url])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while validation_records_so_far(&watched) == 0 {
        assert!(run.try_wait().unwrap().is_none(), "the run ended before its first validation pass was seen");
        assert!(started.elapsed() < Duration::from_secs(600), "no validation pass within 10 minutes");
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(viewer);
    let killed_at = trained_steps(&watched);
    assert!(killed_at < 8, "the viewer was killed only after the run's last step");
    let text = succeeded(&run.wait_with_output().unwrap());
    assert!(text.contains("stopped early"), "the recording says it stopped when the viewer went away:\n{text}");
    assert_eq!(
        common::final_weights(&watched),
        common::final_weights(&unwatched),
        "a viewer killed after step {killed_at} changed the weights"
    );
}

/// How many validation passes a run in progress has recorded.
fn validation_records_so_far(out: &Path) -> usize {
    let Ok(text) = std::fs::read_to_string(out.join("metrics.jsonl")) else { return 0 };
    text.lines().filter(|line| line.contains(r#""kind":"validation""#)).count()
}

#[test]
fn a_refiner_recording_holds_its_steps_and_held_out_pairs_before_and_after() {
    dggt_test_data::parity("difix_tiny_s1");
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/refine-tiny.toml");
    let work = tempfile::tempdir().unwrap();
    let (out, rrd) = (work.path().join("run"), work.path().join("refiner.rrd"));
    let args = ["refine-train", "--config", path(&config), "--steps", "3", "--out", path(&out), "--rerun", path(&rrd)];
    let text = succeeded(&dggt(&args));
    assert!(text.contains("3 steps, 2 validation passes"), "{text}");
    let recording = read_back(&rrd);
    assert_eq!(recording["blueprints"], 1, "the recording carries its layout");
    let entities = recording["entities"].as_object().unwrap();
    for entity in ["/refine/loss", "/refine/l2", "/refine/lpips", "/refine/gram", "/refine/grad_norm"] {
        assert_eq!(steps(entities, entity), [0, 1, 2], "{entity}");
    }
    // The held-out pair before training (step 0) and after (step 3): its render, the refined render, the truth.
    for entity in ["/validation/scores/refined_psnr", "/validation/scores/render_psnr"] {
        assert_eq!(steps(entities, entity), [0, 3], "{entity}");
    }
    for part in ["render", "refined", "target"] {
        assert_eq!(steps(entities, &format!("/validation/pair_0/{part}")), [0, 3], "{part}");
    }
}

/// Two MPI ranks (the `mpi` feature, which CI builds with): rank 0 alone records, so every step is in the
/// recording once, and the other rank neither refuses the file rank 0 created nor writes one.
#[cfg(feature = "mpi")]
#[test]
fn of_two_ranks_rank_zero_alone_records() {
    let work = tempfile::tempdir().unwrap();
    let config = watched_config(work.path(), "ranks", 2);
    let (out, rrd) = (work.path().join("run"), work.path().join("ranks.rrd"));
    let mut command = dggt_test_data::mpi_launcher(2, Path::new(env!("CARGO_BIN_EXE_dggt")));
    command.args(["train", "--config", path(&config), "--out", path(&out), "--rerun", path(&rrd)]);
    let text = succeeded(&command.output().expect("mpirun runs (install openmpi-bin and libopenmpi-dev)"));
    assert_eq!(text.matches("recording: ").count(), 1, "one rank reports a recording:\n{text}");
    let entities = read_back(&rrd)["entities"].as_object().unwrap().clone();
    assert_eq!(steps(&entities, "/train/loss"), [0, 1], "each step once");
    assert_eq!(steps(&entities, "/validation/scores/psnr"), [2]);
}
