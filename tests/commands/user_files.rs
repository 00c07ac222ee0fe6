//! What `dggt` guarantees about a user's files (README, "What dggt guarantees about your files"): a run never
//! trains over another run, a command never writes into a used output folder unless told to replace it, a
//! resumed run keeps its network's shape, and a trained network is run at the input size it was trained at.

use crate::common;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dggt_train::TrainConfig;

fn fixture() -> PathBuf {
    dggt_test_data::fixture("synth-s0")
}

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn text(output: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr))
}

fn succeeded(output: &Output) -> String {
    assert!(output.status.success(), "{}", text(output));
    text(output)
}

fn failed(output: &Output) -> String {
    assert!(!output.status.success(), "succeeded:\n{}", text(output));
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn path(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// The small configuration (a checkpoint every step, two kept), changed by `edit`, written to `dir/name`.
fn write_config(dir: &Path, name: &str, edit: impl FnOnce(&mut TrainConfig)) -> PathBuf {
    let mut config = common::small_config(&dir.join("unused"));
    config.run.checkpoint_every = 1;
    config.run.keep_checkpoints = 2;
    edit(&mut config);
    common::write_config(dir.join(name), &config)
}

fn train(config: &Path, out: &Path, extra: &[&str]) -> Output {
    dggt(&[&["train", "--config", path(config), "--out", path(out)], extra].concat())
}

/// Every file under `root` with its bytes, by path relative to `root`.
fn snapshot(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut stack = vec![root.to_owned()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let file = entry.unwrap().path();
            if file.is_dir() {
                stack.push(file);
            } else {
                files.insert(file.strip_prefix(root).unwrap().to_owned(), std::fs::read(&file).unwrap());
            }
        }
    }
    files
}

/// `train` without `--resume` into a folder holding a run is refused, names the folder and the flags that
/// continue it or train elsewhere, and leaves every file of the run as it was; a new folder, or one holding
/// only the scene index a dry run wrote, is trained into.
#[test]
fn train_refuses_a_folder_holding_a_run_and_leaves_it_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let config = write_config(dir.path(), "train.toml", |c| c.run.steps = 3);
    let run = dir.path().join("run");
    succeeded(&train(&config, &run, &[]));
    let before = snapshot(&run);
    assert!(before.contains_key(Path::new("checkpoints/step-00000003/model.bpk")), "{:?}", before.keys());

    let stderr = failed(&train(&config, &run, &["--steps", "2"]));
    for expected in [path(&run), "already holds a training run", "--resume", "--out"] {
        assert!(stderr.contains(expected), "{expected} missing from\n{stderr}");
    }
    let after = snapshot(&run);
    assert_eq!(before.keys().collect::<Vec<_>>(), after.keys().collect::<Vec<_>>(), "files added or removed");
    assert!(before == after, "a file of the run changed");

    let fresh = dir.path().join("fresh");
    succeeded(&train(&config, &fresh, &["--dry-run"]));
    let trained = succeeded(&train(&config, &fresh, &["--steps", "1"]));
    assert!(trained.contains("trained steps 0..1"), "{trained}");
}

/// A trained run of `steps` steps in `dir/run`, from the small configuration.
fn trained_run(dir: &Path, steps: u64) -> PathBuf {
    let config = write_config(dir, "train.toml", |c| c.run.steps = steps);
    let run = dir.join("run");
    succeeded(&train(&config, &run, &[]));
    run
}

fn reconstruct(run: &Path, out: &Path, extra: &[&str]) -> Output {
    let scene = fixture();
    let args = ["reconstruct", "--images", path(&scene), "--checkpoint", path(run), "--cameras", "0"];
    dggt(&[&args[..], &["--out", path(out)], extra].concat())
}

fn evaluate(run: &Path, out: &Path, extra: &[&str]) -> Output {
    let scene = fixture();
    let args = ["eval", "--scene", path(&scene), "--checkpoint", path(run), "--protocol", "reconstruction"];
    dggt(&[&args[..], &["--frames", "0..2", "--cameras", "0", "--out", path(out)], extra].concat())
}

fn json(file: &Path) -> serde_json::Value {
    let bytes = std::fs::read(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", file.display()))
}

/// `reconstruct` and `eval` refuse a used output folder, naming it and `--overwrite`, and leave it as it was;
/// with `--overwrite` an earlier output of the same command is replaced whole (no file of the first run stays
/// beside the second's), while a folder holding anything else is still left alone.
#[test]
fn reconstruct_and_eval_refuse_a_used_output_folder_unless_told_to_replace_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = trained_run(dir.path(), 1);
    let out = dir.path().join("reconstruction");
    succeeded(&reconstruct(&run, &out, &["--frames", "0..3", "--width", "56"]));
    let first = snapshot(&out);
    let renders = |out: &Path| std::fs::read_dir(out.join("renders")).unwrap().count();
    assert_eq!(renders(&out), 3);

    let stderr = failed(&reconstruct(&run, &out, &["--frames", "0..2", "--width", "56"]));
    for expected in [path(&out), "is not empty", "--overwrite"] {
        assert!(stderr.contains(expected), "{expected} missing from\n{stderr}");
    }
    assert!(snapshot(&out) == first, "the refused run changed the folder");
    succeeded(&reconstruct(&run, &out, &["--frames", "0..2", "--width", "56", "--overwrite"]));
    assert_eq!(renders(&out), 2, "a render of the first run stayed");
    let summary = json(&out.join("summary.json"));
    let files: Vec<&str> = summary["files"].as_array().unwrap().iter().map(|f| f.as_str().unwrap()).collect();
    for file in snapshot(&out).keys() {
        let name = file.to_str().unwrap();
        assert!(name == "summary.json" || files.contains(&name), "{name} is not the second run's");
    }

    let evaluation = dir.path().join("evaluation");
    succeeded(&evaluate(&run, &evaluation, &["--width", "56"]));
    let stderr = failed(&evaluate(&run, &evaluation, &["--width", "56"]));
    assert!(stderr.contains(path(&evaluation)) && stderr.contains("--overwrite"), "{stderr}");
    succeeded(&evaluate(&run, &evaluation, &["--width", "56", "--overwrite"]));

    let notes = dir.path().join("notes");
    std::fs::create_dir(&notes).unwrap();
    std::fs::write(notes.join("todo.txt"), "the user's").unwrap();
    let stderr = failed(&evaluate(&run, &notes, &["--width", "56", "--overwrite"]));
    assert!(stderr.contains("holds no earlier `dggt eval` output"), "{stderr}");
    assert_eq!(std::fs::read_to_string(notes.join("todo.txt")).unwrap(), "the user's");
}

/// A reconstruction whose outputs could outgrow `--max-output-gb` is refused once the network's input size
/// is known, before the forward pass and before anything is written, with the estimate and the flag; within
/// the bound it runs.
#[test]
fn reconstruct_refuses_outputs_over_the_bound_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let run = trained_run(dir.path(), 1);
    let out = dir.path().join("reconstruction");
    let stderr = failed(&reconstruct(&run, &out, &["--frames", "0..2", "--every", "100", "--max-output-gb", "0.001"]));
    for expected in ["101 render times x 1 cameras and 2 input views", "over the bound of 0.00 GB", "--max-output-gb"] {
        assert!(stderr.contains(expected), "{expected} missing from\n{stderr}");
    }
    assert!(!out.exists(), "a refused reconstruction wrote {}", out.display());
    succeeded(&reconstruct(&run, &out, &["--frames", "0..2", "--every", "3"]));
    assert_eq!(std::fs::read_dir(out.join("renders")).unwrap().count(), 4);
}

/// `--resume` with a `[model]` that describes another network is refused, naming the setting and both
/// values, and leaves the run as it was; a changed optimiser setting is applied and reported.
#[test]
fn resume_refuses_another_architecture_and_reports_changed_optimiser_settings() {
    let dir = tempfile::tempdir().unwrap();
    let run = trained_run(dir.path(), 2);
    let before = snapshot(&run);
    let changed = [
        (
            write_config(dir.path(), "no-skip.toml", |c| c.model.pixel_skip = false),
            "model.pixel_skip is true in the checkpoint, false in the configuration",
        ),
        (
            write_config(dir.path(), "dggt.toml", |c| c.model.preset = dggt_model::Preset::Dggt),
            "model.preset is \"tiny\" in the checkpoint, \"dggt\" in the configuration",
        ),
    ];
    for (config, expected) in changed {
        let stderr = failed(&train(&config, &run, &["--resume", "--steps", "3"]));
        assert!(stderr.contains(expected) && stderr.contains(path(&run)), "{expected} missing from\n{stderr}");
        assert!(snapshot(&run) == before, "a refused resume changed the run");
    }

    let lower = write_config(dir.path(), "lower-lr.toml", |c| c.optim.lr = 1e-3);
    let resumed = succeeded(&train(&lower, &run, &["--resume", "--steps", "3"]));
    assert!(resumed.contains("trained steps 2..3"), "{resumed}");
    assert!(resumed.contains("optim.lr is 0.006 in the checkpoint, 0.001 in the configuration"), "{resumed}");
}

/// `--resume` with another input preprocessing or sampler is refused, naming the setting and both values, and
/// leaves the run as it was; `--allow-changed KEY` (the setting, or its section) lets the change through and the
/// run reports it.
#[test]
fn resume_refuses_changed_inputs_unless_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let run = trained_run(dir.path(), 2);
    let before = snapshot(&run);
    let wider = write_config(dir.path(), "wider.toml", |c| c.data.preprocess.target_width = 70);
    let stderr = failed(&train(&wider, &run, &["--resume", "--steps", "3"]));
    let expected = "data.preprocess.target_width is 56 in the checkpoint, 70 in the configuration";
    assert!(stderr.contains(expected) && stderr.contains("--allow-changed"), "{stderr}");
    let more = write_config(dir.path(), "more-targets.toml", |c| c.sampler.targets_per_input += 1);
    let stderr = failed(&train(&more, &run, &["--resume", "--steps", "3", "--allow-changed", "data.preprocess"]));
    assert!(stderr.contains("sampler.targets_per_input is"), "{stderr}");
    assert!(snapshot(&run) == before, "a refused resume changed the run");

    let resumed = succeeded(&train(&more, &run, &["--resume", "--steps", "3", "--allow-changed", "sampler"]));
    assert!(resumed.contains("trained steps 2..3") && resumed.contains("sampler.targets_per_input is"), "{resumed}");
}

/// `reconstruct` and `eval` of a trainer run default to the width it trained at (56 here), an explicit
/// `--width` wins, and a checkpoint that records no preprocessing (an older version's) keeps the release's
/// width and says so.
#[test]
fn reconstruct_and_eval_default_to_the_width_the_run_trained_at() {
    let dir = tempfile::tempdir().unwrap();
    let run = trained_run(dir.path(), 1);
    let width = |out: &Path| json(&out.join("summary.json"))["network_size"][0].as_u64();
    let trained = dir.path().join("trained");
    succeeded(&reconstruct(&run, &trained, &["--frames", "0..2"]));
    assert_eq!(width(&trained), Some(56));
    let wider = dir.path().join("wider");
    succeeded(&reconstruct(&run, &wider, &["--frames", "0..2", "--width", "70"]));
    assert_eq!(width(&wider), Some(70));
    let evaluation = dir.path().join("evaluation");
    succeeded(&evaluate(&run, &evaluation, &[]));
    assert_eq!(json(&evaluation.join("eval.json"))["preprocess"]["target_width"].as_u64(), Some(56));

    // An older version's checkpoint: neither the preprocessing nor the checksums that list it.
    let checkpoint = run.join("checkpoints/step-00000001");
    std::fs::remove_file(checkpoint.join("preprocess.json")).expect("the checkpoint records its preprocessing");
    std::fs::remove_file(checkpoint.join("checksums.json")).expect("the checkpoint lists its files' checksums");
    let older = dir.path().join("older");
    let text = succeeded(&reconstruct(&run, &older, &["--frames", "0..1"]));
    assert!(text.contains("does not record the input preprocessing"), "{text}");
    assert_eq!(width(&older), Some(518));
}
