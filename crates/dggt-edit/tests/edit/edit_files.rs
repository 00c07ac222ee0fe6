//! `write_edits` end to end on a saved ground-truth scene: what it writes, and that a bad edit (unknown id,
//! another Gaussian layout, a source that is not a scene, a camera the scene lacks) is an error naming the
//! argument with nothing written.

use std::path::Path;

use crate::common::{oracle, synth};
use burn::tensor::{Device, Tensor};
use dggt_edit::{Edit, EditOptions, write_edits};
use dggt_formats::ply::read_ply;
use dggt_scene::save_scene;

const FRAMES: [usize; 3] = [0, 4, 8];

fn saved_scene(dir: &Path, seed: u64) -> std::path::PathBuf {
    let scene = oracle(&synth(seed, 9), &FRAMES, &Device::flex());
    let file = dir.join(format!("scene-{seed}.safetensors"));
    save_scene(&scene, &file).unwrap();
    file
}

fn options(scene: &Path, edits: Vec<Edit>) -> EditOptions {
    EditOptions { scene: scene.to_path_buf(), edits, cameras: None, times: Some(vec![0.0, 0.6]) }
}

#[test]
fn an_edit_writes_renders_comparisons_holes_plys_and_its_summary() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, other) = (saved_scene(dir.path(), 0), saved_scene(dir.path(), 1));
    let edits = vec![
        Edit::remove("0").unwrap(),
        Edit::moved("1:0,2,0,15").unwrap(),
        Edit::insert(&format!("{}:0@10,-2,0.8,90", other.display())).unwrap(),
    ];
    let out = dir.path().join("edited");
    std::fs::create_dir(&out).unwrap();
    let summary = write_edits(&options(&scene, edits), &out, &Device::flex()).unwrap();
    assert_eq!(
        summary.edits,
        ["--remove 0", "--move 1:0,2,0,15", &format!("--insert {}:0@10,-2,0.8,90", other.display())]
    );
    assert_eq!(summary.renders.len(), 2, "two times of the one camera");
    for file in &summary.files {
        assert!(out.join(file).is_file(), "{file} listed but not written");
    }
    for k in 0..2 {
        for folder in ["renders", "before_after", "holes"] {
            assert!(summary.files.contains(&format!("{folder}/t{k:04}_cam0.png")), "{folder} {k}");
        }
        let ply = read_ply(&out.join(format!("gaussians/t{k:04}.ply"))).unwrap();
        assert!(ply.to_cloud().unwrap().len() > 1000);
    }
    let side_by_side = image::open(out.join("before_after/t0000_cam0.png")).unwrap();
    assert_eq!((side_by_side.width(), side_by_side.height()), (2 * 96, 64));
    assert!(summary.renders.iter().all(|render| render.changed_pixels > 20), "{:?}", summary.renders);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("edit.json")).unwrap()).unwrap();
    assert_eq!(json["renders"].as_array().unwrap().len(), 2);
}

/// The error of editing `scene` with `edits` into a new folder, which must stay unwritten.
fn refused(scene: &Path, edits: Vec<Edit>, cameras: Option<Vec<usize>>) -> String {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("edited");
    std::fs::create_dir(&out).unwrap();
    let options = EditOptions { cameras, ..options(scene, edits) };
    let message = write_edits(&options, &out, &Device::flex()).expect_err("the edit is refused").to_string();
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 0, "nothing is written for a refused edit: {message}");
    message
}

#[test]
fn bad_edits_are_refused_by_argument_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let scene = saved_scene(dir.path(), 0);
    let message = refused(&scene, vec![Edit::remove("9").unwrap()], None);
    assert!(message.contains("--remove 9") && message.contains("no instance 9"), "{message}");
    let message = refused(&scene, vec![Edit::remove("1").unwrap(), Edit::moved("1:1,0,0,0").unwrap()], None);
    assert!(message.contains("--move 1:1,0,0,0") && message.contains("both removed"), "{message}");
    let message = refused(&scene, vec![Edit::remove("0").unwrap()], Some(vec![2]));
    assert!(message.contains("--cameras") && message.contains("camera 2"), "{message}");

    // A source whose Gaussians carry four colour channels.
    let mut four = dggt_scene::load_scene(&scene, &Device::flex()).unwrap();
    four.pixels.colors = Tensor::zeros([four.pixels.len(), 4], &Device::flex());
    let four_file = dir.path().join("four.safetensors");
    save_scene(&four, &four_file).unwrap();
    let insert = format!("{}:0@0,0,0,0", four_file.display());
    let message = refused(&scene, vec![Edit::insert(&insert).unwrap()], None);
    assert!(message.contains(&format!("--insert {insert}")) && message.contains("layouts differ"), "{message}");

    // A source that is not a saved scene.
    let not_a_scene = dir.path().join("notes.txt");
    std::fs::write(&not_a_scene, "not a scene").unwrap();
    let insert = format!("{}:0@0,0,0,0", not_a_scene.display());
    let message = refused(&scene, vec![Edit::insert(&insert).unwrap()], None);
    assert!(message.contains(&format!("--insert {insert}")) && message.contains("notes.txt"), "{message}");
}
