//! `dggt convert` on real Waymo records and Argoverse 2 logs and on a synthetic nuScenes root: parallel segments,
//! the done marker that makes re-runs skip finished scenes, and `--keep-going` over a damaged segment. The real
//! data lives beside the repository (`../shared/real-data`, or `$DGGT_REAL_DATA`; non-commercial licence, never
//! copied into the repository).

use crate::nuscenes_scene;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn real_data() -> PathBuf {
    dggt_test_data::real_data()
}

/// A folder of three segments: the five-camera frame, the frame without images, and a copy of the first with
/// one payload byte flipped.
fn segments(dir: &Path) -> PathBuf {
    let input = dir.join("segments");
    std::fs::create_dir(&input).unwrap();
    let waymo = real_data().join("waymo");
    std::fs::copy(waymo.join("one_frame_5cams.tfrecord"), input.join("a.tfrecord")).unwrap();
    std::fs::copy(waymo.join("stripped_frame_no_images.tfrecord"), input.join("b.tfrecord")).unwrap();
    let mut damaged = std::fs::read(waymo.join("one_frame_5cams.tfrecord")).unwrap();
    damaged[5000] ^= 0x01;
    std::fs::write(input.join("c.tfrecord"), damaged).unwrap();
    std::fs::write(input.join("notes.txt"), "not a segment").unwrap();
    input
}

fn text(output: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

#[test]
fn convert_waymo_keeps_going_past_a_damaged_segment_and_skips_finished_ones() {
    let dir = tempfile::tempdir().unwrap();
    let input = segments(dir.path());
    let out = dir.path().join("scenes");
    let (input_arg, out_arg) = (input.to_str().unwrap(), out.to_str().unwrap());

    // An interrupted earlier run left a half-written scene: it is started afresh.
    std::fs::create_dir_all(out.join("001.partial")).unwrap();
    std::fs::write(out.join("001.partial/stale.txt"), "from an interrupted run").unwrap();

    let stopped = dggt(&["convert", "waymo", "--input", input_arg, "--out", out_arg, "--workers", "1"]);
    assert!(!stopped.status.success(), "{}", text(&stopped));
    assert!(text(&stopped).contains("c.tfrecord: record 0"), "{}", text(&stopped));

    let kept_going =
        dggt(&["convert", "waymo", "--input", input_arg, "--out", out_arg, "--workers", "2", "--keep-going"]);
    let report = text(&kept_going);
    assert!(!kept_going.status.success(), "a failed segment fails the run: {report}");
    assert!(
        report.contains("failed: ") && report.contains("c.tfrecord: record 0") && report.contains("payload CRC"),
        "{report}"
    );
    assert!(report.contains("1 of 3 segments failed"), "{report}");
    for scene in ["000", "001"] {
        assert!(out.join(scene).join(dggt_convert::DONE_MARKER).is_file(), "{scene}: {report}");
    }
    assert!(!out.join("002").exists() && !out.join("002.partial").join(dggt_convert::DONE_MARKER).exists());
    assert!(!out.join("001/stale.txt").exists() && !out.join("001.partial").exists());
    let images = std::fs::read_dir(out.join("000/images")).unwrap().count();
    assert_eq!(images, 5);

    let again = dggt(&["convert", "waymo", "--input", input_arg, "--out", out_arg, "--scenes", "0,1"]);
    assert!(again.status.success(), "{}", text(&again));
    assert!(
        text(&again).contains("converted 0 segments (0 frames)") && text(&again).contains("2 already done"),
        "{}",
        text(&again)
    );

    let inspect = dggt(&["inspect", out.join("000").to_str().unwrap(), "--json"]);
    assert!(inspect.status.success(), "{}", text(&inspect));
    let summary: serde_json::Value = serde_json::from_slice(&inspect.stdout).unwrap();
    assert_eq!(summary["frames"], 1);
    assert_eq!(summary["cameras"].as_array().unwrap().len(), 5);
}

#[test]
fn convert_waymo_refuses_unknown_cameras_and_missing_input() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scenes");
    let record = real_data().join("waymo/one_frame_5cams.tfrecord");
    let unknown = dggt(&[
        "convert",
        "waymo",
        "--input",
        record.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--cameras",
        "0,7",
    ]);
    assert!(!unknown.status.success());
    assert!(text(&unknown).contains("unknown camera 7"), "{}", text(&unknown));
    let missing = dggt(&["convert", "waymo", "--input", "/no/such/segments", "--out", out.to_str().unwrap()]);
    assert!(!missing.status.success());
    assert!(text(&missing).contains("/no/such/segments"), "{}", text(&missing));

    let front = dggt(&[
        "convert",
        "waymo",
        "--input",
        record.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--cameras",
        "0",
    ]);
    assert!(front.status.success(), "{}", text(&front));
    let images: Vec<_> = std::fs::read_dir(out.join("000/images")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(images, ["000_0.jpg"]);
}

#[test]
fn convert_argoverse2_turns_a_split_folder_into_numbered_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scenes");
    let split = real_data().join("av2/sensor/val");
    let run = dggt(&["convert", "argoverse2", "--input", split.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", text(&run));
    assert!(text(&run).contains("converted 1 segments (2 frames)"), "{}", text(&run));
    let inspect = dggt(&["inspect", out.join("000").to_str().unwrap(), "--json"]);
    assert!(inspect.status.success(), "{}", text(&inspect));
    let summary: serde_json::Value = serde_json::from_slice(&inspect.stdout).unwrap();
    assert_eq!(summary["frames"], 2);
    assert_eq!(summary["cameras"].as_array().unwrap().len(), 7);
    assert_eq!(summary["cameras"][0]["name"], "ring_front_center");
    // By default the images are resampled to the pinhole camera (their own size, re-encoded), and the marker says so.
    let marker: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("000").join(dggt_convert::DONE_MARKER)).unwrap()).unwrap();
    assert_eq!(marker["provenance"]["dataset"], "argoverse2, images undistorted");
    let source =
        std::fs::read_dir(split.join("7fab2350-7eaf-3b7e-a39d-6937a4c1bede/sensors/cameras/ring_front_center"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .min()
            .unwrap();
    let exported = out.join("000/images/000_0.jpg");
    assert_ne!(std::fs::read(&source).unwrap(), std::fs::read(&exported).unwrap());
    assert_eq!(image::image_dimensions(&source).unwrap(), image::image_dimensions(&exported).unwrap());
    let unknown = dggt(&[
        "convert",
        "argoverse2",
        "--input",
        split.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--cameras",
        "7",
    ]);
    assert!(text(&unknown).contains("unknown camera 7: argoverse2 export ids are 0..=6"), "{}", text(&unknown));
}

#[test]
fn convert_nuscenes_numbers_the_scene_table_and_names_a_failed_scene() {
    let dir = tempfile::tempdir().unwrap();
    // A second scene row whose first sample belongs to the first scene.
    let root = nuscenes_scene::write_root(dir.path(), |tables| {
        let scenes = tables.iter_mut().find(|(name, _)| *name == "scene").unwrap().1.as_array_mut().unwrap();
        let mut broken = scenes[0].clone();
        broken["token"] = "scene-1".into();
        broken["name"] = "scene-0062".into();
        broken["first_sample_token"] = "sample-1".into();
        scenes.push(broken);
    });
    let out = dir.path().join("scenes");
    let args = ["convert", "nuscenes", "--input", root.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let run = dggt(&[&args[..], &["--keep-going", "--sky-masks", "lidar"]].concat());
    let report = text(&run);
    assert!(!run.status.success(), "{report}");
    assert!(report.contains("1 of 2 segments failed"), "{report}");
    assert!(report.contains("scene-0062") && report.contains("sample.json") && report.contains("sample-1"), "{report}");
    assert!(out.join("000").join(dggt_convert::DONE_MARKER).is_file(), "{report}");
    assert_eq!(std::fs::read_dir(out.join("000/sky_masks")).unwrap().count(), 2 * 6 + 1, "masks and the note");
    assert!(!out.join("001").exists());

    let again = dggt(&[&args[..], &["--scenes", "0", "--version", "v1.0-mini", "--sky-masks", "lidar"]].concat());
    assert!(again.status.success() && text(&again).contains("1 already done"), "{}", text(&again));
    let without_sky = dggt(&[&args[..], &["--scenes", "0"]].concat());
    assert!(!without_sky.status.success(), "{}", text(&without_sky));
    assert!(text(&without_sky).contains("with sky masks lidar (this run: none)"), "{}", text(&without_sky));
    let missing = dggt(&[
        "convert",
        "nuscenes",
        "--input",
        root.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--version",
        "v1.0-trainval",
    ]);
    let report = text(&missing);
    assert!(!missing.status.success() && report.contains("v1.0-trainval: no such nuScenes version folder"), "{report}");
    assert!(report.contains("holds v1.0-mini"), "{report}");
}

/// Any version folder holding the devkit tables converts (the official test split's `v1.0-test` among them);
/// a version folder lacking a table is refused naming the table's file.
#[test]
fn convert_nuscenes_reads_any_version_folder_that_holds_the_tables() {
    let dir = tempfile::tempdir().unwrap();
    let root = nuscenes_scene::write_root(dir.path(), |_| {});
    std::fs::rename(root.join("v1.0-mini"), root.join("v1.0-test")).unwrap();
    let out = dir.path().join("scenes");
    let args = ["convert", "nuscenes", "--input", root.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let converted = dggt(&[&args[..], &["--version", "v1.0-test"]].concat());
    assert!(converted.status.success(), "{}", text(&converted));
    assert!(out.join("000").join(dggt_convert::DONE_MARKER).is_file(), "{}", text(&converted));

    std::fs::create_dir(root.join("v1.0-custom")).unwrap();
    std::fs::copy(root.join("v1.0-test/scene.json"), root.join("v1.0-custom/scene.json")).unwrap();
    let lacking = dggt(&[&args[..], &["--version", "v1.0-custom"]].concat());
    assert!(!lacking.status.success(), "{}", text(&lacking));
    assert!(text(&lacking).contains("v1.0-custom/sample.json"), "{}", text(&lacking));
    let path = dggt(&[&args[..], &["--version", "../elsewhere"]].concat());
    assert!(!path.status.success() && text(&path).contains("is not a folder name"), "{}", text(&path));
}

/// A scene is skipped only when its done marker records this run's source and options. Any other conversion
/// into its place (other cameras, another record, an Argoverse 2 log) is refused naming what differs and the
/// flag that converts it again, and leaves the scene as it was; a scene folder without a marker is refused in
/// plain words, with no partial folder left behind.
#[test]
fn convert_argoverse2_with_depth_flows_writes_maps_the_loader_reads_and_records_the_option() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scenes");
    let log = real_data().join("av2/sensor/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede");
    let convert = |extra: &[&str]| {
        let args = ["convert", "argoverse2", "--input", log.to_str().unwrap(), "--out", out.to_str().unwrap()];
        dggt(&[&args[..], &["--cameras", "1,2", "--argoverse-lens", "as-recorded"], extra].concat())
    };
    let run = convert(&["--depth-flows", "boxes"]);
    assert!(run.status.success(), "{}", text(&run));
    let inspect = dggt(&["inspect", out.join("000").to_str().unwrap(), "--json"]);
    assert!(inspect.status.success(), "{}", text(&inspect));
    let summary: serde_json::Value = serde_json::from_slice(&inspect.stdout).unwrap();
    assert_eq!(summary["depth_flows"], true, "{summary}");
    assert_eq!(summary["scene_flow"], "tracked_boxes", "{summary}");
    let marker: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("000").join(dggt_convert::DONE_MARKER)).unwrap()).unwrap();
    assert_eq!(marker["provenance"]["depth_flows"], "boxes");
    let without = convert(&[]);
    assert!(!without.status.success(), "{}", text(&without));
    assert!(text(&without).contains("with depth flows boxes (this run: none)"), "{}", text(&without));
}

#[test]
fn convert_skips_a_scene_only_when_its_marker_records_the_same_conversion() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scenes");
    let record = real_data().join("waymo/one_frame_5cams.tfrecord");
    let convert = |dataset: &str, input: &Path, out: &Path, extra: &[&str]| {
        let args = ["convert", dataset, "--input", input.to_str().unwrap(), "--out", out.to_str().unwrap()];
        dggt(&[&args[..], extra].concat())
    };
    let first = convert("waymo", &record, &out, &["--cameras", "0"]);
    assert!(first.status.success(), "{}", text(&first));
    let scene = out.join("000");
    let marker = std::fs::read(scene.join(dggt_convert::DONE_MARKER)).unwrap();
    let images = || std::fs::read_dir(scene.join("images")).unwrap().count();
    assert_eq!(images(), 1);

    let copy = dir.path().join("other.tfrecord");
    std::fs::copy(&record, &copy).unwrap();
    let log = real_data().join("av2/sensor/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede");
    let refusals = [
        (convert("waymo", &record, &out, &[]), "with cameras [0] (this run: [0, 1, 2, 3, 4])"),
        (convert("waymo", &copy, &out, &["--cameras", "0"]), "with source "),
        (convert("argoverse2", &log, &out, &["--cameras", "0", "--argoverse-lens", "as-recorded"]), "with source "),
    ];
    for (refused, reason) in refusals {
        let report = text(&refused);
        assert!(!refused.status.success(), "{report}");
        for expected in [scene.to_str().unwrap(), reason, "--overwrite", "1 refused"] {
            assert!(report.contains(expected), "{expected} missing from\n{report}");
        }
        assert_eq!(std::fs::read(scene.join(dggt_convert::DONE_MARKER)).unwrap(), marker, "{report}");
        assert_eq!(images(), 1, "{report}");
    }

    let same = convert("waymo", &record, &out, &["--cameras", "0"]);
    assert!(same.status.success() && text(&same).contains("1 already done"), "{}", text(&same));
    let replaced = convert("waymo", &record, &out, &["--overwrite"]);
    assert!(replaced.status.success() && text(&replaced).contains("converted 1 segments"), "{}", text(&replaced));
    assert_eq!(images(), 5);
    assert!(!out.join("000.partial").exists() && !out.join("000.replaced").exists());

    let bare = dir.path().join("bare");
    std::fs::create_dir_all(bare.join("000")).unwrap();
    std::fs::write(bare.join("000/notes.txt"), "the user's").unwrap();
    let unmarked = convert("waymo", &record, &bare, &[]);
    let report = text(&unmarked);
    assert!(!unmarked.status.success(), "{report}");
    assert!(report.contains("has no convert_done.json") && !report.contains("os error"), "{report}");
    assert!(bare.join("000/notes.txt").is_file() && !bare.join("000.partial").exists(), "{report}");
}
