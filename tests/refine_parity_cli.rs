//! `dggt parity` on the refiner's reference vectors: recognises the folder, passes in both modes, and fails
//! naming the tensor when a reference is perturbed.
//!
//! The vectors are `$DGGT_PARITY_DIR/difix_tiny_s1` when that variable names the shared parity folder, else
//! `<repo>/../shared/parity/difix_tiny_s1`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn vectors() -> PathBuf {
    let root = std::env::var_os("DGGT_PARITY_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/parity"));
    let dir = root.join("difix_tiny_s1");
    assert!(
        dir.join("model_difix.pkl").is_file(),
        "refiner parity vectors not found at {} (set DGGT_PARITY_DIR to the shared parity folder)",
        dir.display()
    );
    dir
}

fn stdout(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn a_refiner_folder_passes_in_both_modes() {
    let dir = vectors();
    let out = dggt(&["parity", "--vectors", dir.to_str().unwrap()]);
    let text = stdout(&out);
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    for name in ["prompt_embeds", "single.unet.eps", "single.image_out", "ref.unet.mid", "ref.image_out"] {
        let row = text.lines().find(|line| line.split_whitespace().next() == Some(name)).expect(name);
        assert!(row.ends_with("pass"), "{row}");
    }
    assert!(text.contains(" 0 fail"), "{text}");
}

#[test]
fn a_perturbed_reference_fails_naming_the_tensor() {
    let dir = vectors();
    let copy = tempfile::tempdir().unwrap();
    for name in ["inputs.safetensors", "model_difix.pkl"] {
        std::fs::copy(dir.join(name), copy.path().join(name)).unwrap();
    }
    std::os::unix::fs::symlink(dir.join("base"), copy.path().join("base")).unwrap();
    let bytes = std::fs::read(dir.join("outputs.safetensors")).unwrap();
    let tensors = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut owned: Vec<(String, Vec<u8>, Vec<usize>)> =
        tensors.tensors().into_iter().map(|(name, view)| (name, view.data().to_vec(), view.shape().to_vec())).collect();
    let (_, data, _) = owned.iter_mut().find(|(name, _, _)| name == "ref.dec.skip.2").unwrap();
    let value = f32::from_le_bytes(data[..4].try_into().unwrap()) + 0.01;
    data[..4].copy_from_slice(&value.to_le_bytes());
    let views = owned.iter().map(|(name, data, shape)| {
        (name.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape.clone(), data).unwrap())
    });
    safetensors::serialize_to_file(views, None, &copy.path().join("outputs.safetensors")).unwrap();

    let out = dggt(&["parity", "--vectors", copy.path().to_str().unwrap()]);
    assert!(!out.status.success(), "a perturbed reference passed:\n{}", stdout(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("ref.dec.skip.2"), "{stderr}");
    assert!(stdout(&out).contains(" 1 fail"), "{}", stdout(&out));
}
