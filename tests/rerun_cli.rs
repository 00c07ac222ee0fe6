//! `dggt reconstruct --rerun`: a tiny network trained one step reconstructs three frames of the fixture's
//! two cameras, and the recording is read back with rerun's own Python SDK (`rerun-sdk` of the crate's version,
//! `tests/rerun_readback.py`) as a client would: its entity paths, the splats at every rendered time, the
//! cameras' poses and the time lines' values match `summary.json`, `cameras.json` and the PLY files.

use std::path::Path;
use std::process::{Command, Output};

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
