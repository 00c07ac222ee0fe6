//! `dggt refine` on the tiny random refiner of the parity vectors (random weights: plumbing, shapes and
//! determinism are checked, not quality): `dggt parity` recognises the refiner folder, passes it in both
//! modes and names a perturbed tensor; `convert` writes a safetensors checkpoint that `dggt parity`
//! passes with, `images` writes one refined image per input, reproducibly, in both modes, `reconstruct
//! --refine` writes refined renders beside the unrefined, and `bench refiner` times frames.
//!
//! The vectors are `$DGGT_PARITY_DIR/difix_tiny_s1` when that variable names the shared parity folder, else
//! `<repo>/../shared/parity/difix_tiny_s1`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dggt_formats::images::{read_rgb_png, write_rgb_png};
use dggt_geom::ImageSize;

fn dggt(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dggt")).args(args).output().expect("the dggt binary runs")
}

fn vectors() -> PathBuf {
    let dir = dggt_test_data::parity("difix_tiny_s1");
    assert!(
        dir.join("model_difix.pkl").is_file(),
        "refiner parity vectors not found at {} (set DGGT_PARITY_DIR to the shared parity folder)",
        dir.display()
    );
    dir
}

fn succeeded(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    stdout
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_converted_checkpoint_passes_parity() {
    let dir = vectors();
    let out = tempfile::tempdir().unwrap();
    let converted = out.path().join("model_difix.safetensors");
    let text = succeeded(&dggt(&[
        "refine",
        "convert",
        "--checkpoint",
        path(&dir.join("model_difix.pkl")),
        "--out",
        path(&converted),
    ]));
    assert!(text.contains("208 UNet and 74 VAE tensors, 35 LoRA targets at rank 4 (alpha 8)"), "{text}");
    let text = succeeded(&dggt(&["parity", "--vectors", path(&dir), "--weights", path(&converted)]));
    assert!(text.contains(" 0 fail"), "{text}");
}

/// A 20 x 30 gradient (sides not multiples of 8).
fn write_test_image(path: &Path, shift: f32) {
    let size = ImageSize::new(30, 20).unwrap();
    let rgb: Vec<f32> = (0..size.area() * 3).map(|i| (i as f32 * 0.013 + shift) % 1.0).collect();
    write_rgb_png(path, size, &rgb).unwrap();
}

#[test]
fn images_are_refined_to_their_size_reproducibly_in_both_modes() {
    let dir = vectors();
    let work = tempfile::tempdir().unwrap();
    let (a, b) = (work.path().join("a.png"), work.path().join("b.png"));
    write_test_image(&a, 0.0);
    write_test_image(&b, 0.5);
    let (base, checkpoint) = (dir.join("base"), dir.join("model_difix.pkl"));
    let refine = |out: &str, extra: &[&str]| {
        let out = work.path().join(out);
        let mut args = vec!["refine", "images", "--model", path(&base), "--image", path(&a)];
        args.extend_from_slice(&["--image", path(&b), "--prompt-ids", "5,7,9", "--out", path(&out)]);
        args.extend_from_slice(&["--checkpoint", path(&checkpoint)]);
        args.extend_from_slice(extra);
        assert!(succeeded(&dggt(&args)).contains("2 refined images"));
        let read = |name: &str| read_rgb_png(&out.join(name)).unwrap();
        let ((size_a, rgb_a), (size_b, _)) = (read("a.png"), read("b.png"));
        assert_eq!((size_a.width, size_a.height, size_b.width, size_b.height), (30, 20, 30, 20));
        rgb_a
    };
    let mean = refine("mean", &[]);
    let sampled = refine("sampled", &["--sample-latent", "--seed", "3"]);
    assert_eq!(sampled, refine("sampled_again", &["--sample-latent", "--seed", "3"]), "same seed, same image");
    let with_reference = refine("reference", &["--reference", path(&b), "--reference", path(&a)]);
    let differs = |x: &[f32], y: &[f32]| x.iter().zip(y).any(|(p, q)| (p - q).abs() > 1.5 / 255.0);
    assert!(differs(&mean, &sampled), "sampling the latent changed nothing");
    assert!(differs(&mean, &with_reference), "the reference view changed nothing");
    let original = read_rgb_png(&a).unwrap().1;
    assert!(differs(&mean, &original), "the refiner returned its input");
}

#[test]
fn a_model_folder_without_tokenizer_or_checkpoint_is_named_in_the_error() {
    let dir = vectors();
    let work = tempfile::tempdir().unwrap();
    let image = work.path().join("a.png");
    write_test_image(&image, 0.0);
    let base = dir.join("base");
    let refined = work.path().join("refined");
    let args = ["refine", "images", "--model", path(&base), "--image", path(&image), "--out", path(&refined)];
    let out = dggt(&args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("model_difix.pkl") && stderr.contains(path(&base)), "{stderr}");
    let checkpoint = dir.join("model_difix.pkl");
    let out = dggt(&[&args[..], &["--checkpoint", path(&checkpoint)]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("tokenizer/vocab.json"), "{stderr}");
    let out = dggt(&["reconstruct", "--images", "x", "--checkpoint", "y", "--out", "z", "--refine-checkpoint", "c"]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--refine"));
    let out = dggt(&[&args[..], &["--checkpoint", path(&checkpoint), "--precision", "f64"]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("f16-unet"), "{stderr}");
}

#[test]
fn the_refiner_benchmark_times_frames_at_a_folders_sizes() {
    let base = vectors().join("base");
    let args = ["bench", "refiner", "--model", path(&base), "--height", "20", "--width", "30", "--repeat", "2"];
    let text = succeeded(&dggt(&[&args[..], &["--reference-view", "--precision", "bf16"]].concat()));
    let expected = [
        "frame: 30 x 20 (ReferenceView)",
        "precision bf16,",
        "per frame: median",
        "of 2 runs",
        "peak memory: ",
        "resident memory: ",
    ];
    for expected in expected {
        assert!(text.contains(expected), "{expected} missing from\n{text}");
    }
    assert!(!text.contains("unknown"), "peak memory is read on Linux:\n{text}");

    // A made-up folder at the same sizes, written, then loaded from disk with its fresh checkpoint.
    let work = tempfile::tempdir().unwrap();
    let folder = work.path().join("model");
    let text = succeeded(&dggt(&["bench", "refiner", "--model", path(&base), "--write-model", path(&folder)]));
    assert!(text.contains("wrote a made-up model folder") && folder.join("model_difix.safetensors").is_file());
    let again = dggt(&["bench", "refiner", "--model", path(&base), "--write-model", path(&folder)]);
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(!again.status.success() && stderr.contains("is not empty") && stderr.contains("--overwrite"), "{stderr}");
    let args = ["bench", "refiner", "--model", path(&folder), "--load", "--height", "20", "--width", "30"];
    let text = succeeded(&dggt(&[&args[..], &["--repeat", "1"]].concat()));
    assert!(text.contains("weights loaded from disk") && text.contains("load (files read"), "{text}");
}

/// `dggt reconstruct --refine --refine-reference nearest-input`: a tiny network trained one step renders two
/// frames of the fixture; each render is refined into `renders_refined/` under its name and size, the
/// unrefined one kept, attending to the input image the summary names as its nearest input (the same as
/// `dggt refine images` with that reference, and not what the single-view mode gives).
#[test]
fn reconstruct_writes_refined_renders_beside_the_unrefined() {
    let dir = vectors();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let work = tempfile::tempdir().unwrap();
    let (run, out) = (work.path().join("run"), work.path().join("reconstruction"));
    let config = repo.join("configs/tiny-overfit.toml");
    succeeded(&dggt(&["train", "--config", path(&config), "--steps", "1", "--out", path(&run)]));
    let (base, checkpoint) = (dir.join("base"), dir.join("model_difix.pkl"));
    let text = succeeded(&dggt(&[
        "reconstruct",
        "--images",
        path(&dggt_test_data::fixture("synth-s0")),
        "--checkpoint",
        path(&run),
        "--cameras",
        "0",
        "--frames",
        "0..2",
        "--width",
        "56",
        "--out",
        path(&out),
        "--refine",
        path(&base),
        "--refine-checkpoint",
        path(&checkpoint),
        "--refine-prompt-ids",
        "5,7,9",
        "--refine-reference",
        "nearest-input",
    ]));
    assert!(text.contains("refined 2 renders into") && text.contains("unrefined kept in renders/"), "{text}");
    let names = |folder: &str| {
        let mut names: Vec<_> = std::fs::read_dir(out.join(folder)).unwrap().map(|e| e.unwrap().file_name()).collect();
        names.sort();
        names
    };
    assert_eq!(names("renders").len(), 2);
    assert_eq!(names("renders"), names("renders_refined"));
    for name in names("renders") {
        let (size, render) = read_rgb_png(&out.join("renders").join(&name)).unwrap();
        let (refined_size, refined) = read_rgb_png(&out.join("renders_refined").join(&name)).unwrap();
        assert_eq!(size, refined_size);
        assert_ne!(render, refined, "{name:?} unchanged by the refiner");
    }

    // At the input times each render's nearest input is the input view of that time.
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let renders = summary["renders"].as_array().unwrap();
    let nearest: Vec<&str> = renders.iter().map(|r| r["nearest_input"].as_str().unwrap()).collect();
    assert!(nearest[0] != nearest[1] && nearest.iter().all(|n| out.join(n).is_file()), "{nearest:?}");
    let render = renders[0]["file"].as_str().unwrap();
    let refine_alone = |reference: Option<&str>, folder: &str| {
        let folder = work.path().join(folder);
        let mut args = vec!["refine", "images", "--model", path(&base), "--checkpoint", path(&checkpoint)];
        args.extend(["--prompt-ids", "5,7,9", "--out", path(&folder)]);
        let image = out.join(render);
        let reference = reference.map(|r| out.join(r));
        args.extend(["--image", path(&image)]);
        if let Some(reference) = &reference {
            args.extend(["--reference", path(reference)]);
        }
        succeeded(&dggt(&args));
        read_rgb_png(&folder.join(image.file_name().unwrap())).unwrap().1
    };
    let refined = read_rgb_png(&out.join("renders_refined").join(Path::new(render).file_name().unwrap())).unwrap().1;
    assert_eq!(refined, refine_alone(Some(nearest[0]), "with-reference"));
    assert_ne!(refined, refine_alone(None, "single-view"), "the reference view made no difference");

    // A second run into a used folder is refused before any work; `--overwrite` replaces the earlier output.
    let (folder, image) = (work.path().join("single-view"), out.join(render));
    let mut again = vec!["refine", "images", "--model", path(&base), "--checkpoint", path(&checkpoint)];
    again.extend(["--prompt-ids", "5,7,9", "--image", path(&image), "--out", path(&folder)]);
    let refused = dggt(&again);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && stderr.contains("is not empty") && stderr.contains("--overwrite"), "{stderr}");
    assert!(folder.join("refined.json").is_file(), "refine images records what it refined");
    succeeded(&dggt(&[&again[..], &["--overwrite"]].concat()));

    // The reconstruction edited and refined from its saved scene: the renders refined under their names.
    let edited = work.path().join("edited");
    let mut edit =
        vec!["edit", "--scene", path(&out), "--remove-box", "-0.5,-0.5,0,0.5,0.5,1000", "--out", path(&edited)];
    edit.extend(["--refine", path(&base), "--refine-checkpoint", path(&checkpoint), "--refine-prompt-ids", "5,7,9"]);
    let text = succeeded(&dggt(&edit));
    assert!(text.contains("refined 2 renders into"), "{text}");
    let edited_renders: Vec<_> =
        std::fs::read_dir(edited.join("renders")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(edited_renders.len(), 2);
    for name in edited_renders {
        assert!(edited.join("renders_refined").join(&name).is_file(), "{name:?} not refined");
    }
    let nearest = dggt(&[&edit[..], &["--refine-reference", "nearest-input"]].concat());
    assert!(!nearest.status.success() && String::from_utf8_lossy(&nearest.stderr).contains("--refine-reference"));
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
