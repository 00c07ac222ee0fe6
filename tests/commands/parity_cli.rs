//! `dggt parity` on the shared reference vectors: passes from every weight file, names what a perturbed
//! reference breaks, and says clearly when the folder is missing.
//!
//! The vectors are `$DGGT_PARITY_DIR/dggt_tiny_s3_56x70` when that variable names the shared parity folder,
//! else `<repo>/../shared/parity/dggt_tiny_s3_56x70`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use safetensors::{Dtype, SafeTensors, tensor::TensorView};

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn vectors() -> PathBuf {
    dggt_test_data::parity("dggt_tiny_s3_56x70")
}

fn text(out: &Output) -> (String, String) {
    (String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// The table's row of `name`.
fn row<'a>(stdout: &'a str, name: &str) -> &'a str {
    stdout
        .lines()
        .find(|line| line.split_whitespace().next() == Some(name))
        .unwrap_or_else(|| panic!("no row {name} in\n{stdout}"))
}

/// Whether the row of `name` has the status `status` (`pass` or `FAIL`).
fn has_status(stdout: &str, name: &str, status: &str) -> bool {
    row(stdout, name).split_whitespace().any(|word| word == status)
}

fn assert_passes(args: &[&str]) -> String {
    let out = dggt(args);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{args:?} failed:\n{stdout}\n{stderr}");
    for name in ["agg.output_list.3", "pose_enc", "depth", "gs_conf", "means.world", "sky.colors"] {
        assert!(has_status(&stdout, name, "pass"), "{}", row(&stdout, name));
    }
    assert!(has_status(&stdout, "render.final_rgb", "pass"), "{}", row(&stdout, "render.final_rgb"));
    assert!(stdout.contains(" 0 fail,"), "{stdout}");
    stdout
}

#[test]
fn passes_from_the_default_weights() {
    let dir = vectors();
    let stdout = assert_passes(&["parity", "--vectors", dir.to_str().unwrap()]);
    print!("{stdout}");
}

/// The same vectors through the CubeCL kernels (on CI, Mesa's software Vulkan driver): every network output and
/// every render within tolerance, so both kernel sets reproduce the release.
#[cfg(feature = "wgpu-backend")]
#[test]
fn passes_on_wgpu() {
    let dir = vectors();
    let stdout = assert_passes(&["parity", "--vectors", dir.to_str().unwrap(), "--device", "wgpu"]);
    for name in ["render.fg_rgb", "render.fg_alpha", "render.fg_expected_depth", "render.final_rgb"] {
        assert!(has_status(&stdout, name, "pass"), "{}", row(&stdout, name));
    }
}

#[test]
fn passes_from_the_pytorch_checkpoints() {
    let dir = vectors();
    for file in ["weights.pt", "weights_cuda_storage.pt", "weights.safetensors"] {
        let weights = dir.join(file);
        assert_passes(&[
            "parity",
            "--vectors",
            dir.to_str().unwrap(),
            "--device",
            "cpu",
            "--weights",
            weights.to_str().unwrap(),
        ]);
    }
}

/// Writes `source` to `target` with `delta` added to every value of the tensor `name`, and with a copy of that
/// tensor under `extra` when given.
fn write_perturbed(source: &Path, target: &Path, name: &str, delta: f32, extra: Option<&str>) {
    let bytes = std::fs::read(source).unwrap();
    let file = SafeTensors::deserialize(&bytes).unwrap();
    let tensors: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = file
        .tensors()
        .into_iter()
        .map(|(key, view)| {
            let mut data = view.data().to_vec();
            if key == name {
                assert_eq!(view.dtype(), Dtype::F32, "{key} stored as f32");
                for chunk in data.chunks_exact_mut(4) {
                    let value = f32::from_le_bytes(chunk.try_into().unwrap()) + delta;
                    chunk.copy_from_slice(&value.to_le_bytes());
                }
            }
            (key, view.dtype(), view.shape().to_vec(), data)
        })
        .collect();
    let copy = tensors.iter().find(|(key, ..)| key == name).cloned().expect("the tensor is in the file");
    let tensors: Vec<_> =
        tensors.into_iter().chain(extra.map(|extra| (extra.to_string(), copy.1, copy.2, copy.3))).collect();
    let views = tensors
        .iter()
        .map(|(key, dtype, shape, data)| (key.as_str(), TensorView::new(*dtype, shape.clone(), data).unwrap()));
    safetensors::serialize_to_file(views, None, target).unwrap();
}

/// A copy of the vectors whose outputs file is written by `write` (from the source file to the copy's).
fn copied_vectors(write: impl FnOnce(&Path, &Path)) -> tempfile::TempDir {
    let source = vectors();
    let copy = tempfile::tempdir().unwrap();
    for file in ["config.json", "inputs.safetensors", "weights.safetensors"] {
        std::fs::copy(source.join(file), copy.path().join(file)).unwrap();
    }
    write(&source.join("outputs.safetensors"), &copy.path().join("outputs.safetensors"));
    copy
}

#[test]
fn a_perturbed_output_fails_by_name() {
    let copy = copied_vectors(|source, target| write_perturbed(source, target, "depth", 1e-2, None));
    let out = dggt(&["parity", "--vectors", copy.path().to_str().unwrap()]);
    let (stdout, stderr) = text(&out);
    assert!(!out.status.success(), "a perturbed reference must fail:\n{stdout}");
    assert!(has_status(&stdout, "depth", "FAIL"), "{stdout}");
    assert!(has_status(&stdout, "depth_conf", "pass"), "{stdout}");
    assert!(stdout.contains(" 1 fail,"), "{stdout}");
    assert!(stderr.contains("1 output(s) failed parity: depth"), "{stderr}");
}

/// A reference output the port has no rule for is never compared, and that fails the command.
#[test]
fn an_output_never_compared_fails() {
    let copy =
        copied_vectors(|source, target| write_perturbed(source, target, "depth", 0.0, Some("track_head.coords")));
    let out = dggt(&["parity", "--vectors", copy.path().to_str().unwrap()]);
    let (stdout, stderr) = text(&out);
    assert!(!out.status.success(), "an output never compared must fail:\n{stdout}");
    assert!(has_status(&stdout, "depth", "pass"), "{stdout}");
    assert!(
        row(&stdout, "track_head.coords").contains("FAIL (not compared: not an output this port knows)"),
        "{stdout}"
    );
    assert!(stdout.contains(" 1 fail, 1 of them not compared"), "{stdout}");
    assert!(stderr.contains("1 output(s) failed parity: track_head.coords"), "{stderr}");
}

#[test]
fn missing_vectors_are_a_clear_error() {
    let out = dggt(&["parity", "--vectors", "/no/such/vectors"]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(stderr.contains("parity vectors at /no/such/vectors: no such folder"), "{stderr}");

    let empty = tempfile::tempdir().unwrap();
    std::fs::copy(vectors().join("config.json"), empty.path().join("config.json")).unwrap();
    let out = dggt(&["parity", "--vectors", empty.path().to_str().unwrap()]);
    let (_, stderr) = text(&out);
    assert!(!out.status.success());
    assert!(stderr.contains("inputs.safetensors is missing"), "{stderr}");
}
