//! `dggt refine-train` on `configs/refine-tiny.toml` (the tiny random refiner of the shared parity folder):
//! trains a few steps, writes metrics, checkpoints and the refiner file, resumes where it stopped, and refuses
//! a bad configuration naming the file and the setting; `dggt refine-pairs` writes per-sample shards that a
//! rerun keeps and training reads, and survives a damaged image in the export.

use crate::common;
use std::path::PathBuf;
use std::process::{Command, Output};

use dggt_train::TrainConfig;

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn config() -> PathBuf {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("configs/refine-tiny.toml");
    dggt_test_data::parity("difix_tiny_s1");
    path
}

fn stdout(output: &Output) -> String {
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    String::from_utf8_lossy(&output.stdout).into_owned()
}

#[test]
fn refine_train_trains_checkpoints_exports_and_resumes() {
    let out = tempfile::tempdir().unwrap();
    let out_dir = out.path().to_str().unwrap();
    let config = config();
    let config = config.to_str().unwrap();
    let first = stdout(&dggt(&["refine-train", "--config", config, "--steps", "3", "--out", out_dir]));
    assert!(first.contains("trained steps 0..3"), "{first}");
    assert!(out.path().join("refiner.safetensors").is_file() && out.path().join("checkpoints/latest").is_file());
    let resumed = stdout(&dggt(&["refine-train", "--config", config, "--steps", "5", "--out", out_dir, "--resume"]));
    assert!(resumed.contains("trained steps 3..5"), "{resumed}");
    let metrics = std::fs::read_to_string(out.path().join("metrics.jsonl")).unwrap();
    let train_steps = metrics.lines().filter(|l| l.contains("\"train\"")).count();
    assert_eq!(train_steps, 5, "one record per step:\n{metrics}");
}

#[test]
fn refine_train_refuses_a_bad_configuration_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    let text = std::fs::read_to_string(config()).unwrap().replace("batch = 1", "batch = 0");
    std::fs::write(&bad, text).unwrap();
    let output = dggt(&["refine-train", "--config", bad.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("bad.toml") && stderr.contains("run.batch"), "{stderr}");
}

/// `dggt refine-pairs --shards`: one pairs file per sample of a reconstruction run, kept when the command runs
/// again (only the missing samples render), and `refine-train` trains on the folder.
#[test]
fn refine_pairs_writes_shards_that_a_rerun_keeps_and_training_reads() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let work = tempfile::tempdir().unwrap();
    let (run, shards) = (work.path().join("run"), work.path().join("shards"));
    let overfit = repo.join("configs/tiny-overfit.toml");
    let path = |p: &PathBuf| p.to_str().unwrap().to_string();
    stdout(&dggt(&["train", "--config", &path(&overfit), "--steps", "1", "--out", &path(&run)]));
    let pairs = |samples: &str| {
        let args = ["refine-pairs", "--config", &path(&overfit), "--run", &path(&run), "--samples", samples];
        stdout(&dggt(&[&args[..], &["--shards", "--out", &path(&shards)]].concat()))
    };
    let first = pairs("0..2");
    assert!(first.contains("from 2 samples rendered (0 kept") && first.contains("at step 1"), "{first}");
    let shard = |i: usize| shards.join(format!("sample-{i:06}.safetensors"));
    assert!(shard(0).is_file() && shard(1).is_file());
    std::fs::remove_file(shard(1)).unwrap();
    let written = std::fs::metadata(shard(0)).unwrap().modified().unwrap();
    let second = pairs("0..3");
    assert!(second.contains("from 2 samples rendered (1 kept"), "{second}");
    assert_eq!(std::fs::metadata(shard(0)).unwrap().modified().unwrap(), written, "sample 0 was rewritten");

    // Shards of another checkpoint never join them: a folder recording another source is refused, naming it.
    let record = shards.join("pairs-source.json");
    let recorded = std::fs::read_to_string(&record).unwrap();
    std::fs::write(&record, recorded.replace("\"step\": 1", "\"step\": 7")).unwrap();
    let args = ["refine-pairs", "--config", &path(&overfit), "--run", &path(&run), "--samples", "0..3", "--shards"];
    let other = dggt(&[&args[..], &["--out", &path(&shards)]].concat());
    let stderr = String::from_utf8_lossy(&other.stderr);
    assert!(!other.status.success() && stderr.contains("\"step\":7") && stderr.contains("--overwrite"), "{stderr}");
    std::fs::write(&record, recorded).unwrap();

    // The refiner trains on the folder (the tiny configuration with absolute paths and rendered pairs).
    let shared = dggt_test_data::Shared::Parity.dir().join("..");
    let text = std::fs::read_to_string(config()).unwrap().replace("\"../../shared", &format!("\"{}", shared.display()));
    let images = text.lines().find(|l| l.starts_with("images = ")).unwrap().to_string();
    let text = text.replace(&images, &format!("rendered = \"{}\"", shards.display()));
    let refine_config = work.path().join("refine.toml");
    std::fs::write(&refine_config, text).unwrap();
    let out = work.path().join("refiner");
    let trained =
        stdout(&dggt(&["refine-train", "--config", &path(&refine_config), "--steps", "2", "--out", &path(&out)]));
    assert!(trained.contains("trained steps 0..2"), "{trained}");
}

/// A damaged image in the export: the samples that need it are skipped with a warning naming the file, and
/// `refine-pairs` still writes the pairs of the others.
#[test]
fn refine_pairs_survives_a_damaged_image_and_names_it() {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let work = tempfile::tempdir().unwrap();
    let scene = work.path().join("scene");
    copy_folder(&repo.join("data-fixtures/synth-s0"), &scene);
    let damaged = scene.join("images/012_0.jpg");
    let bytes = std::fs::read(&damaged).unwrap();
    std::fs::write(&damaged, &bytes[..400]).unwrap();
    let mut overfit = TrainConfig::load(&repo.join("configs/tiny-overfit.toml")).unwrap();
    overfit.data.scene = scene;
    // 5-6 inputs and one target per input: most samples leave frame 12 out, so the damaged sample's retry loads.
    (overfit.sampler.min_inputs, overfit.sampler.max_inputs) = (5, 6);
    (overfit.sampler.targets_per_input, overfit.sampler.target_margin) = (1, 0);
    let config = common::write_config(work.path().join("overfit.toml"), &overfit);
    let (run, out) = (work.path().join("run"), work.path().join("pairs.safetensors"));
    let path = |p: &PathBuf| p.to_str().unwrap().to_string();
    let args = ["refine-pairs", "--config", &path(&config), "--run", &path(&run), "--samples", "0..6"];
    let output = dggt(&[&args[..], &["--out", &path(&out)]].concat());
    let text = stdout(&output);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("sample skipped") && stderr.contains("012_0.jpg"), "{stderr}");
    assert!(text.contains("from 6 samples rendered") && out.is_file(), "{text}");
    let again = dggt(&[&args[..], &["--out", &path(&out)]].concat());
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(!again.status.success() && stderr.contains("exists") && stderr.contains("--overwrite"), "{stderr}");
}

fn copy_folder(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_folder(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}
