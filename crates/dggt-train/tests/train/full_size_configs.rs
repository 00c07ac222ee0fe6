//! The full-size configurations (`configs/dggt-waymo.toml`, `configs/dggt-finetune.toml`) built end to end
//! with a tiny stand-in: the tiny architecture in place of the 1.35B one, the shared parity weights (release
//! key names) in place of the checkpoints — only their VGGT-1B part for the Waymo configuration, so the
//! Gaussian, dynamic and sky parts start fresh as they would from VGGT-1B — the LPIPS-Alex weights of the
//! metrics vectors, and the bundled fixture in place of the scene. One step must train the Gaussian, dynamic and
//! sky parts and leave the frozen parts untouched. The vectors are under `$DGGT_PARITY_DIR` (the shared parity folder).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Tensor};
use dggt_train::{DepthFlowMaps, Start, TrainConfig, Trainer};

fn repo() -> PathBuf {
    dggt_test_data::repo_root()
}

fn parity_dir() -> PathBuf {
    dggt_test_data::parity("dggt_tiny_s3_56x70");
    dggt_test_data::Shared::Parity.dir()
}

/// The parity weights restricted to the parts a VGGT-1B checkpoint has.
fn vggt_stand_in(dir: &Path) -> PathBuf {
    let bytes = std::fs::read(parity_dir().join("dggt_tiny_s3_56x70/weights.safetensors")).unwrap();
    let tensors = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let kept: Vec<(String, safetensors::tensor::TensorView)> = tensors
        .tensors()
        .into_iter()
        .filter(|(name, _)| {
            ["aggregator.", "camera_head.", "depth_head.", "point_head."].iter().any(|p| name.starts_with(p))
        })
        .collect();
    assert!(kept.len() > 50 && kept.len() < tensors.len(), "{} of {} tensors kept", kept.len(), tensors.len());
    let path = dir.join("vggt-stand-in.safetensors");
    safetensors::serialize_to_file(kept, None, &path).unwrap();
    path
}

/// Every parameter, by top-level module, flattened.
fn parameters_by_module(trainer: &Trainer) -> HashMap<String, Vec<f32>> {
    struct Collect {
        path: Vec<String>,
        out: HashMap<String, Vec<f32>>,
    }
    impl ModuleVisitor for Collect {
        fn enter_module(&mut self, name: &str, _container_type: &str) {
            self.path.push(name.to_string());
        }
        fn exit_module(&mut self, _name: &str, _container_type: &str) {
            self.path.pop();
        }
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let top = self.path.first().cloned().unwrap_or_default();
            let values = param.val().into_data().convert::<f32>().try_into_vec::<f32>().unwrap();
            self.out.entry(top).or_default().extend(values);
        }
    }
    let mut collect = Collect { path: Vec::new(), out: HashMap::new() };
    trainer.model().visit(&mut collect);
    collect.out
}

fn stand_in(config: &str, init: PathBuf, out: &Path) -> TrainConfig {
    let mut config = TrainConfig::load(&repo().join("configs").join(config)).unwrap();
    let lpips = parity_dir().join("metrics/lpips_alex.safetensors");
    config.model.preset = dggt_model::Preset::Tiny;
    config.model.init_checkpoint = Some(init);
    config.data.scene = repo().join("data-fixtures/synth-s0");
    config.data.preprocess.target_width = 56;
    config.data.preprocess.crop_to_square = true;
    config.data.workers = 1;
    config.sampler.min_inputs = 4;
    config.sampler.max_inputs = 4;
    config.sampler.window = 8;
    config.loss.lpips_weights = Some(lpips.clone());
    config.loss.lpips_backbone = Some(lpips);
    config.run.out_dir = out.to_path_buf();
    config.run.devices = vec!["cpu".into()];
    config.validate().unwrap();
    config
}

fn one_step_trains_only_the_unfrozen_parts(config: TrainConfig) {
    let frozen = config.optim.frozen.clone();
    assert_eq!(frozen, ["aggregator", "camera_head", "depth_head"], "the release's frozen parts");
    assert!(config.loss.lpips > 0.0, "LPIPS is part of the release's loss");
    let mut trainer = Trainer::new(config, vec![Device::flex()], Start::Fresh).unwrap();
    let validation = trainer.validate().unwrap().expect("the configuration validates");
    assert!(validation.psnr.is_finite() && validation.views.len() == 3, "{validation:?}");
    let before = parameters_by_module(&trainer);
    let sample = trainer.sample(0).unwrap();
    let record = trainer.train_step(&[sample], 1.0, DepthFlowMaps::Skip).unwrap();
    let lpips = record.measures.as_ref().and_then(|m| m.terms.get("lpips").copied());
    assert!(lpips.is_some_and(f64::is_finite), "{record:?}");
    let after = parameters_by_module(&trainer);
    // The losses reach the Gaussian, dynamic and sky parts; the frozen parts and the heads no loss reads
    // (point, semantic) stay as they were.
    let trained = ["gs_head", "instance_head", "sky_model"];
    for module in trained.iter().chain(&frozen.iter().map(String::as_str).collect::<Vec<_>>()) {
        assert!(before.contains_key(*module), "the stand-in has no {module}");
    }
    for (module, values) in &before {
        let changed = values != &after[module];
        assert_eq!(changed, trained.contains(&module.as_str()), "module {module}: changed = {changed}");
    }
}

#[test]
fn waymo_configuration_builds_from_a_vggt_stand_in_and_trains_the_new_heads() {
    let dir = tempfile::tempdir().unwrap();
    let init = vggt_stand_in(dir.path());
    let config = stand_in("dggt-waymo.toml", init, &dir.path().join("run"));
    one_step_trains_only_the_unfrozen_parts(config);
}

#[test]
fn finetune_configuration_builds_from_release_named_weights() {
    let dir = tempfile::tempdir().unwrap();
    let init = parity_dir().join("dggt_tiny_s3_56x70/weights.pt");
    let config = stand_in("dggt-finetune.toml", init, &dir.path().join("run"));
    one_step_trains_only_the_unfrozen_parts(config);
}
