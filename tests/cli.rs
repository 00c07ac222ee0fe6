//! The `dggt` command line as a newcomer uses it.

use std::process::{Command, Output};

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn fixture() -> String {
    format!("{}/data-fixtures/synth-s0", env!("CARGO_MANIFEST_DIR"))
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
    let length = summary["trajectory_length_m"].as_f64().unwrap();
    assert!((10.0..25.0).contains(&length), "{length}");

    let text = dggt(&["inspect", &fixture(), "--frames", "5..10", "--cameras", "0"]);
    assert!(text.status.success());
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(stdout.contains("frames     5 (indices 5..=9"), "{stdout}");
    assert!(stdout.contains("FRONT") && !stdout.contains("FRONT_LEFT"), "{stdout}");
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

#[test]
fn devices_checks_the_default_cpu_backend() {
    let out = dggt(&["devices", "--device", "cpu"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stdout));
    assert!(String::from_utf8_lossy(&out.stdout).contains("Cpu: ok"));
}
