//! Full-size name and shape check: the `dggt` and `vggt_1b` presets, built lazily (no weights allocated), must
//! take every tensor of the released checkpoints' key lists (`shared/reference/checkpoint-keys/*.tsv`) under
//! the prefixes they build, with the same shapes, and have no parameter those lists lack. The only tensors
//! left over are the tracker's, which is not built.
//!
//! The lists are read in place (`../../../shared/reference/checkpoint-keys` from this crate) or from
//! `DGGT_CHECKPOINT_KEYS_DIR`.

use std::collections::BTreeMap;

use burn::tensor::Device;
use dggt_model::weights::{module_path, parameters};
use dggt_model::{Dggt, ModelConfig};

fn key_list(name: &str) -> Vec<(String, Vec<usize>)> {
    let path = dggt_test_data::Shared::CheckpointKeys.entry(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!("reading {}: {e} (set DGGT_CHECKPOINT_KEYS_DIR to the checkpoint-keys folder)", path.display())
    });
    text.lines()
        .filter(|line| !line.trim().is_empty())
        .map(|line| {
            let (key, shape) = line.split_once('\t').unwrap_or_else(|| panic!("bad line {line:?}"));
            let shape = shape
                .trim_matches(|c| c == '(' || c == ')')
                .split(',')
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .map(|s| s.parse().unwrap_or_else(|_| panic!("bad shape in {line:?}")))
                .collect();
            (key.to_string(), shape)
        })
        .collect()
}

/// Checks `config` against the key list `tsv`; returns the keys left for parts not built, or the problems.
fn check(config: &ModelConfig, tsv: &str) -> Result<Vec<String>, Vec<String>> {
    let model = Dggt::new(config, &Device::flex()).expect("valid preset");
    let prefixes = model.built_prefixes();
    let mut params: BTreeMap<String, (Vec<usize>, String)> =
        parameters(&model).into_iter().map(|p| (p.path, (p.shape, p.container))).collect();
    let mut leftover = vec![];
    let mut errors = vec![];
    for (key, shape) in key_list(tsv) {
        if !prefixes.iter().any(|p| key.starts_with(p)) {
            leftover.push(key);
            continue;
        }
        let path = module_path(&key);
        // burn-store's PyTorch adapter names LayerNorm parameters gamma/beta and transposes Linear weights.
        let layer_norm_path = path
            .strip_suffix(".weight")
            .map(|p| format!("{p}.gamma"))
            .or_else(|| path.strip_suffix(".bias").map(|p| format!("{p}.beta")));
        let found = match params.remove(&path) {
            Some(found) => Some(found),
            None => layer_norm_path.and_then(|p| params.remove(&p)).filter(|(_, c)| c == "Struct:LayerNorm"),
        };
        match found {
            None => errors.push(format!("{key}: no parameter at {path}")),
            Some((burn_shape, container)) => {
                let mut expected = shape.clone();
                if container == "Struct:Linear" && key.ends_with(".weight") {
                    expected.reverse();
                }
                if burn_shape != expected {
                    errors.push(format!("{key}: checkpoint {shape:?}, network {burn_shape:?} ({container})"));
                }
            }
        }
    }
    errors.extend(params.keys().map(|path| format!("network parameter {path} is not in {tsv}")));
    if errors.is_empty() { Ok(leftover) } else { Err(errors) }
}

fn check_ok(config: &ModelConfig, tsv: &str) -> Vec<String> {
    check(config, tsv).unwrap_or_else(|errors| panic!("{tsv}: {} problems:\n{}", errors.len(), errors.join("\n")))
}

#[test]
fn dggt_preset_matches_release_checkpoint() {
    let leftover = check_ok(&ModelConfig::dggt(), "dggt-release.tsv");
    assert!(leftover.iter().all(|k| k.starts_with("track_head.")), "unexpected leftover keys");
}

#[test]
fn vggt_1b_preset_matches_vggt_checkpoint() {
    let leftover = check_ok(&ModelConfig::vggt_1b(), "vggt-1b.tsv");
    assert!(leftover.iter().all(|k| k.starts_with("track_head.")), "unexpected leftover keys");
}

#[test]
fn mismatching_presets_are_caught() {
    let errors = check(&ModelConfig::tiny(), "dggt-release.tsv").expect_err("tiny sizes differ from the release");
    assert!(errors.iter().any(|e| e.starts_with("aggregator.patch_embed.pos_embed: checkpoint [1, 1370, 1024]")));
    // VGGT-1B has no Gaussian, instance or semantic head, so the DGGT preset has parameters it lacks.
    let errors = check(&ModelConfig::dggt(), "vggt-1b.tsv").expect_err("DGGT heads are not in VGGT-1B");
    assert!(errors.iter().any(|e| e.starts_with("network parameter gs_head.")));
}
