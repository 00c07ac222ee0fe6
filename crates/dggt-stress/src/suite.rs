//! The suite: every case with what it must do, each run in isolation (a panic is caught and reported as a
//! failure, never ends the run), and the report by case and by stage.
//!
//! A case passes when nothing it probed is non-finite or broken and it ends as expected: most must run to the
//! end; inputs that are invalid (a NaN depth) must instead be rejected with an error that says what is wrong.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;

use burn::tensor::{Device, FloatDType};
use dggt_geom::ImageSize;
use dggt_infer::{CameraSource, RenderSection, fresh_model};
use dggt_model::ModelConfig;
use dggt_model::sky::SkyModel;
use dggt_objective::{LossWeights, Objective};
use dggt_scene::DynamicMotion;
use dggt_scene::MeansGradient;
use serde::Serialize;

use crate::crafted::{self, LIFESPAN, OPACITY, Prediction, RGB, ROTATION, SCALE};
use crate::error::StressError;
use crate::geometry;
use crate::network;
use crate::probe::{Finding, Probe, Stage};
use crate::scenario::Scenario;
use dggt_data::random::SplitMix64;

/// How a case must end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Expect {
    /// Run to the end with every probed value finite.
    Finite,
    /// Be rejected with an error (the input is invalid), with nothing non-finite probed before that.
    Rejected,
}

/// Which cases the suite runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StressScope {
    /// Every case at small sizes: CI's suite on the CPU.
    #[default]
    Bounded,
    /// Every case with larger scenarios and more random extreme mixtures.
    Full,
    /// What a device adds to the CPU suite, at a fraction of its cost: every crafted case (the rasteriser's
    /// kernels, scene assembly, the objective and the backward pass at their extremes) and the first network
    /// case in `f32` (the network's forward and backward through the device's kernels once). The network's
    /// other extremes exercise the same operations as on the CPU; on a device every new shape compiles (and,
    /// with autotune, tunes) its kernels, which on a software driver costs minutes a case.
    Device,
}

/// What to run.
#[derive(Debug, Clone, Default)]
pub struct StressOptions {
    /// Which cases, at which sizes.
    pub scope: StressScope,
    /// A folder holding `lpips_alex.safetensors` and `vgg16_features.safetensors` (the layout of the shared
    /// metrics vectors): adds the LPIPS and Gram terms to the objective.
    pub loss_weights: Option<PathBuf>,
}

/// The result of one case.
#[derive(Debug, Clone, Serialize)]
pub struct CaseOutcome {
    pub group: &'static str,
    pub name: String,
    pub expect: Expect,
    pub findings: Vec<Finding>,
    /// The error the pipeline returned, if any.
    pub error: Option<String>,
    /// The panic message, if the case panicked.
    pub panic: Option<String>,
    /// Values checked, per stage in [`Stage::ALL`] order.
    pub checked: Vec<usize>,
    /// Why the case did not run on this device (a float type it lacks); listed, never counted as a pass.
    pub skipped: Option<String>,
    /// Wall-clock seconds the case took (kernel compilation and tuning included on a GPU's first use).
    pub seconds: f64,
}

impl CaseOutcome {
    /// Ran, and ended as expected with nothing non-finite or broken.
    pub fn passed(&self) -> bool {
        self.skipped.is_none() && self.ran_clean()
    }

    /// Did not fail: passed, or skipped.
    pub fn acceptable(&self) -> bool {
        self.skipped.is_some() || self.ran_clean()
    }

    fn ran_clean(&self) -> bool {
        self.panic.is_none()
            && self.findings.is_empty()
            && match self.expect {
                Expect::Finite => self.error.is_none(),
                Expect::Rejected => self.error.is_some(),
            }
    }
}

/// Every case's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct StressReport {
    pub device: String,
    pub scope: StressScope,
    pub cases: Vec<CaseOutcome>,
}

impl StressReport {
    /// No case failed (skipped ones are listed in the table).
    pub fn passed(&self) -> bool {
        self.cases.iter().all(CaseOutcome::acceptable)
    }

    pub fn failures(&self) -> impl Iterator<Item = &CaseOutcome> {
        self.cases.iter().filter(|c| !c.acceptable())
    }

    pub fn skipped(&self) -> impl Iterator<Item = &CaseOutcome> {
        self.cases.iter().filter(|c| c.skipped.is_some())
    }

    /// Non-finite or broken values found at each stage, over all cases.
    pub fn bad_values_by_stage(&self) -> BTreeMap<Stage, usize> {
        let mut by_stage: BTreeMap<Stage, usize> = Stage::ALL.iter().map(|&s| (s, 0)).collect();
        for finding in self.cases.iter().flat_map(|c| &c.findings) {
            *by_stage.entry(finding.stage).or_default() += finding.bad;
        }
        by_stage
    }

    /// A plain-text table: one row per case, then the findings of the failed ones and the totals by stage.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ =
            writeln!(out, "{:<9} {:<44} {:<8} {:>12} {:>8}  result", "group", "case", "expect", "values", "seconds");
        for case in &self.cases {
            let result = match (&case.skipped, case.passed()) {
                (Some(reason), _) => format!("skipped: {reason}"),
                (None, true) => "pass".into(),
                (None, false) => "FAIL".into(),
            };
            let expect = match case.expect {
                Expect::Finite => "finite",
                Expect::Rejected => "rejected",
            };
            let values: usize = case.checked.iter().sum();
            let _ = writeln!(
                out,
                "{:<9} {:<44} {expect:<8} {values:>12} {:>8.1}  {result}",
                case.group, case.name, case.seconds
            );
        }
        for case in self.failures() {
            let _ = writeln!(out, "\n{} / {}:", case.group, case.name);
            if let Some(panic) = &case.panic {
                let _ = writeln!(out, "  panicked: {panic}");
            }
            match (&case.error, case.expect) {
                (Some(error), Expect::Finite) => {
                    let _ = writeln!(out, "  unexpected error: {error}");
                }
                (None, Expect::Rejected) => {
                    let _ = writeln!(out, "  accepted an invalid input without an error");
                }
                _ => {}
            }
            for finding in &case.findings {
                let _ = writeln!(out, "  {finding}");
            }
        }
        let failed = self.failures().count();
        let _ = writeln!(out, "\nbad values by stage:");
        for (stage, count) in self.bad_values_by_stage() {
            let _ = writeln!(out, "  {:<10} {count}", stage.name());
        }
        let skipped = self.skipped().count();
        let passed = self.cases.len() - failed - skipped;
        let _ = writeln!(out, "{} cases: {passed} pass, {failed} fail, {skipped} skipped", self.cases.len());
        out
    }
}

/// What a case does with its probe.
type CaseRun<'a> = Box<dyn FnOnce(&mut Probe) -> Result<(), StressError> + 'a>;

/// A case to run on the geometry alone.
type GeometryCase = fn(&mut Probe) -> Result<(), StressError>;

/// A case to run: its identity, and what it does with a probe.
struct Case<'a> {
    group: &'static str,
    name: String,
    expect: Expect,
    run: CaseRun<'a>,
}

fn run_case(case: Case<'_>) -> CaseOutcome {
    tracing::info!("stress case {} / {}", case.group, case.name);
    let mut probe = Probe::default();
    let run = case.run;
    let started = std::time::Instant::now();
    let result = catch_unwind(AssertUnwindSafe(|| run(&mut probe)));
    let seconds = started.elapsed().as_secs_f64();
    let (error, panic) = match result {
        Ok(Ok(())) => (None, None),
        Ok(Err(error)) => (Some(error.to_string()), None),
        Err(payload) => {
            let message = payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "a panic without a message".into());
            (None, Some(message))
        }
    };
    CaseOutcome {
        group: case.group,
        name: case.name,
        expect: case.expect,
        checked: Stage::ALL.iter().map(|&s| probe.checked(s)).collect(),
        findings: probe.into_findings(),
        error,
        panic,
        skipped: None,
        seconds,
    }
}

/// A case that cannot run on this device, and why.
fn skipped_case(group: &'static str, name: String, reason: String) -> CaseOutcome {
    tracing::info!("stress case {group} / {name}: skipped ({reason})");
    CaseOutcome {
        group,
        name,
        expect: Expect::Finite,
        findings: Vec::new(),
        error: None,
        panic: None,
        checked: vec![0; Stage::ALL.len()],
        skipped: Some(reason),
        seconds: 0.0,
    }
}

/// `f16`, `bf16`, `f32`.
fn dtype_name(dtype: FloatDType) -> &'static str {
    match dtype {
        FloatDType::F16 => "f16",
        FloatDType::BF16 => "bf16",
        FloatDType::F64 => "f64",
        _ => "f32",
    }
}

/// An edit of a hand-made prediction (and of the scenario's masks) that makes one extreme.
type Edit = fn(&mut Scenario, &mut Prediction, &mut SplitMix64);

/// The hand-made extremes: name, expectation, edit.
fn crafted_extremes() -> Vec<(&'static str, Expect, Edit)> {
    vec![
        ("moderate values", Expect::Finite, |_, _, _| {}),
        ("opacities at 0", Expect::Finite, |_, p, _| p.set_channels(OPACITY, -1e4)),
        ("opacities at 1, no sky", Expect::Finite, |s, p, _| {
            p.set_channels(OPACITY, 1e4);
            s.fill_sky(0.0);
        }),
        ("opacities at 1, all sky", Expect::Finite, |s, p, _| {
            p.set_channels(OPACITY, 1e4);
            s.fill_sky(1.0);
        }),
        ("opacities at 0, no sky", Expect::Finite, |s, p, _| {
            p.set_channels(OPACITY, -1e4);
            s.fill_sky(0.0);
        }),
        ("lifespan near 0 (1e-4)", Expect::Finite, |_, p, _| p.set_channels(LIFESPAN, 1e4)),
        ("lifespan near 0 (1e-30)", Expect::Finite, |_, p, _| p.set_channels(LIFESPAN, 1e30)),
        ("lifespan huge (1e6)", Expect::Finite, |_, p, _| p.set_channels(LIFESPAN, -1e4)),
        ("degenerate scales", Expect::Finite, |_, p, _| p.set_channels(SCALE, -1e4)),
        ("huge scales", Expect::Finite, |_, p, _| p.set_channels(SCALE, 1e4)),
        ("anisotropic scales", Expect::Finite, |_, p, _| {
            for pixel in p.raw.chunks_exact_mut(crafted::RAW_CHANNELS) {
                pixel[SCALE].copy_from_slice(&[1e3, -1e4, 0.0]);
            }
        }),
        ("zero quaternions", Expect::Finite, |_, p, _| p.set_channels(ROTATION, 0.0)),
        ("saturated colours", Expect::Finite, |_, p, r| p.scatter_channels(RGB, &[-1e4, 1e4], r)),
        ("depth 0", Expect::Finite, |_, p, _| p.depth.fill(0.0)),
        ("depth 1e6", Expect::Finite, |_, p, _| p.depth.fill(1e6)),
        ("depth mixed 0 .. 1e6", Expect::Finite, |_, p, r| {
            p.depth.iter_mut().for_each(|d| *d = r.pick(&[0.0, 1e-8, 1.0, 1e6]));
        }),
        ("no dynamic pixels", Expect::Finite, |s, p, _| {
            p.dynamic_logit.fill(-1e4);
            s.fill_dynamic(0.0);
        }),
        ("all pixels dynamic", Expect::Finite, |s, p, _| {
            all_dynamic(s, p);
        }),
        ("black images, all sky", Expect::Finite, |s, _, _| {
            s.fill_images(0.0);
            s.fill_sky(1.0);
        }),
        ("moderate velocities", Expect::Finite, |_, p, r| p.set_velocity(1.0, r)),
        ("huge velocities (1e6 per frame)", Expect::Finite, |_, p, r| p.set_velocity(1e6, r)),
        ("huge velocities, all dynamic", Expect::Finite, |s, p, r| {
            p.set_velocity(1e6, r);
            all_dynamic(s, p);
        }),
        // A flat wall of dynamic pixels: each view one object, followed through every input.
        ("instances, all pixels dynamic", Expect::Finite, |s, p, _| {
            p.motion = DynamicMotion::Instances;
            flat_dynamic_wall(s, p);
        }),
        ("instances, huge velocities, all dynamic", Expect::Finite, |s, p, r| {
            p.motion = DynamicMotion::Instances;
            p.set_velocity(1e6, r);
            flat_dynamic_wall(s, p);
        }),
        ("instances, depth mixed 0 .. 1e6", Expect::Finite, |_, p, r| {
            p.motion = DynamicMotion::Instances;
            p.dynamic_logit.iter_mut().for_each(|l| *l = r.pick(&[-30.0, 30.0]));
            p.depth.iter_mut().for_each(|d| *d = r.pick(&[0.0, 1e-8, 1.0, 1e6]));
        }),
        ("learnt flow, moderate values", Expect::Finite, |_, p, _| p.motion = DynamicMotion::Learnt),
        // A flat wall of dynamic pixels: every pixel a query, neighbours at equal distances.
        ("learnt flow, all pixels dynamic", Expect::Finite, |s, p, _| {
            p.motion = DynamicMotion::Learnt;
            flat_dynamic_wall(s, p);
        }),
        ("learnt flow, huge displacements (x1e6)", Expect::Finite, |s, p, _| {
            p.motion = DynamicMotion::Learnt;
            p.flow.gain = 1e6;
            all_dynamic(s, p);
        }),
        // Every point of a view at its camera centre: no spacing within a cloud.
        ("learnt flow, depth 0", Expect::Finite, |_, p, _| {
            p.motion = DynamicMotion::Learnt;
            p.depth.fill(0.0);
        }),
        ("learnt flow, depth mixed 0 .. 1e6", Expect::Finite, |_, p, r| {
            p.motion = DynamicMotion::Learnt;
            p.dynamic_logit.iter_mut().for_each(|l| *l = r.pick(&[-30.0, 30.0]));
            p.depth.iter_mut().for_each(|d| *d = r.pick(&[0.0, 1e-8, 1.0, 1e6]));
        }),
        ("learnt flow, huge features (1e4)", Expect::Finite, |_, p, r| {
            p.motion = DynamicMotion::Learnt;
            p.flow.features.iter_mut().for_each(|f| *f = r.pick(&[-1e4, 1e4]));
        }),
        ("learnt flow, NaN feature", Expect::Rejected, |_, p, _| {
            p.motion = DynamicMotion::Learnt;
            p.dynamic_logit.fill(1e4);
            p.flow.features[3] = f32::NAN;
        }),
        ("NaN velocity", Expect::Rejected, |_, p, r| {
            p.set_velocity(1.0, r);
            p.velocity.as_mut().unwrap()[4] = f32::NAN;
        }),
        ("NaN depth", Expect::Rejected, |_, p, _| p.depth[5] = f32::NAN),
        ("infinite depth", Expect::Rejected, |_, p, _| p.depth[0] = f32::INFINITY),
    ]
}

/// Every pixel predicted and masked dynamic.
fn all_dynamic(scenario: &mut Scenario, prediction: &mut Prediction) {
    prediction.dynamic_logit.fill(1e4);
    scenario.fill_dynamic(1.0);
}

/// A flat wall of dynamic pixels 10 m away: each view one object, every pixel's neighbours at equal distances.
fn flat_dynamic_wall(scenario: &mut Scenario, prediction: &mut Prediction) {
    prediction.depth.fill(10.0);
    all_dynamic(scenario, prediction);
}

/// Every channel, depth, logit and mask drawn from extremes at random.
fn mixed_extremes(scenario: &mut Scenario, prediction: &mut Prediction, random: &mut SplitMix64) {
    let extremes = [-1e4, -30.0, 0.0, 30.0, 1e4];
    prediction.scatter_channels(0..crafted::RAW_CHANNELS, &extremes, random);
    prediction.depth.iter_mut().for_each(|d| *d = random.pick(&[0.0, 1e-6, 1.0, 1e6]));
    prediction.dynamic_logit.iter_mut().for_each(|l| *l = random.pick(&extremes));
    for view in &mut scenario.views {
        view.sky.iter_mut().for_each(|v| *v = random.pick(&[0.0, 1.0]));
        view.dynamic.iter_mut().for_each(|v| *v = random.pick(&[0.0, 1.0]));
        view.image.iter_mut().for_each(|v| *v = random.pick(&[0.0, 1.0]));
    }
}

fn loss_weights(options: &StressOptions, camera: f64) -> LossWeights {
    let mut weights =
        LossWeights { camera, depth: 0.1, gram: 0.01, flow: 0.1, learnt_flow: 0.1, ..LossWeights::default() };
    if let Some(dir) = &options.loss_weights {
        let lpips = dir.join("lpips_alex.safetensors");
        weights.lpips_weights = Some(lpips.clone());
        weights.lpips_backbone = Some(lpips);
        weights.gram_backbone = Some(dir.join("vgg16_features.safetensors"));
    }
    weights
}

/// Runs the suite on `device` (training runs on its autodiff form).
pub fn run_suite(options: &StressOptions, device: &Device) -> Result<StressReport, StressError> {
    let device = device.clone().autodiff();
    let mut outcomes = geometry_group();
    let config = ModelConfig::tiny();
    outcomes.extend(crafted_group(options, &config, &device)?);
    outcomes.extend(network_group(options, &config, &device)?);
    Ok(StressReport { device: format!("{device:?}"), scope: options.scope, cases: outcomes })
}

/// Camera geometry at its extremes: rotations, translations, timelines, pose encodings.
fn geometry_group() -> Vec<CaseOutcome> {
    let geometry_cases: [(&str, GeometryCase); 5] = [
        ("SLERP between near-identical rotations", geometry::near_identical_rotations),
        ("SLERP between opposite rotations", geometry::opposite_rotations),
        ("huge translations", geometry::huge_translations),
        ("timelines: one frame, repeats, huge indices", geometry::timelines),
        ("extreme pose encodings", geometry::extreme_pose_encodings),
    ];
    geometry_cases
        .into_iter()
        .map(|(name, run)| {
            run_case(Case { group: "geometry", name: name.into(), expect: Expect::Finite, run: Box::new(run) })
        })
        .collect()
}

/// Network outputs crafted at their extremes (no network runs), through the scene, the objective and the
/// backward pass, with ground-truth cameras.
fn crafted_group(
    options: &StressOptions,
    config: &ModelConfig,
    device: &Device,
) -> Result<Vec<CaseOutcome>, StressError> {
    let sky_config = config.sky_model.clone().ok_or(StressError::NoSkyModel)?;
    let sky_model = SkyModel::initialised(&sky_config, device);
    let crafted_render = RenderSection {
        cameras: CameraSource::GroundTruth,
        means_gradient: MeansGradient::Through,
        ..RenderSection::default()
    };
    let crafted_objective = Objective::new(loss_weights(options, 0.0), crafted_render, device)?;
    let full = options.scope == StressScope::Full;
    let (size, inputs) = if full { (ImageSize::new(70, 56), 3) } else { (ImageSize::new(56, 42), 2) };
    let size = size?;
    let mut crafted_cases: Vec<(String, Expect, Edit)> =
        crafted_extremes().into_iter().map(|(name, expect, edit)| (name.to_string(), expect, edit)).collect();
    for seed in 0..if full { 16 } else { 2 } {
        crafted_cases.push((format!("random extremes, seed {seed}"), Expect::Finite, mixed_extremes));
    }
    let mut outcomes = Vec::new();
    for (index, (name, expect, edit)) in crafted_cases.into_iter().enumerate() {
        let (objective, sky_model) = (&crafted_objective, &sky_model);
        outcomes.push(run_case(Case {
            group: "crafted",
            name,
            expect,
            run: Box::new(move |probe| {
                let mut scenario = Scenario::new(size, inputs, 2, index as u64);
                // One moderate prediction under every case, so that each differs from the others only by the
                // extreme it names (and a device meets the same tensor shapes again, its kernels compiled once).
                let mut prediction = Prediction::random(&scenario, CRAFTED_PREDICTION_SEED);
                edit(&mut scenario, &mut prediction, &mut SplitMix64::new(1000 + index as u64));
                crafted::run(probe, &scenario, &prediction, objective, sky_model, device)
            }),
        }));
    }
    Ok(outcomes)
}

/// The seed of the moderate prediction every crafted case starts from.
const CRAFTED_PREDICTION_SEED: u64 = 0;

/// One network case: name, image size, input frames, how the scenario is set up, and whether it also runs in
/// f16 and bf16.
type NetworkCase = (&'static str, ImageSize, usize, fn(&mut Scenario), bool);

/// The network's own cases: extreme images, masks and input counts through the fresh tiny network with its own
/// predicted cameras, the objective and the backward pass.
fn network_cases(options: &StressOptions) -> Result<Vec<NetworkCase>, StressError> {
    let normal = ImageSize::new(70, 56)?;
    let small = ImageSize::new(42, 42)?;
    let many = if options.scope == StressScope::Full { (normal, 64) } else { (small, 64) };
    Ok(vec![
        ("random images", normal, 3, |_| {}, true),
        (
            "black images, all sky",
            normal,
            3,
            |s| {
                s.fill_images(0.0);
                s.fill_sky(1.0);
            },
            true,
        ),
        (
            "white images, no sky",
            normal,
            3,
            |s| {
                s.fill_images(1.0);
                s.fill_sky(0.0);
            },
            true,
        ),
        (
            "grey images, all dynamic",
            normal,
            3,
            |s| {
                s.fill_images(0.5);
                s.fill_dynamic(1.0);
            },
            false,
        ),
        ("a single input frame", normal, 1, |_| {}, false),
        ("64 input frames", many.0, many.1, |_| {}, true),
    ])
}

/// Every network case in f32; those marked also with the network computing in f16 and in bf16 (parameters,
/// activations and constants; the scene is assembled and rendered in f32), trained in that type, where the
/// device declares the type.
fn network_group(
    options: &StressOptions,
    config: &ModelConfig,
    device: &Device,
) -> Result<Vec<CaseOutcome>, StressError> {
    let model = fresh_model(config, None, 0, device)?;
    let network_render = RenderSection {
        cameras: CameraSource::Predicted,
        means_gradient: MeansGradient::Through,
        ..RenderSection::default()
    };
    let network_objective = Objective::new(loss_weights(options, 1.0), network_render.clone(), device)?;
    let network_cases = network_cases(options)?;
    let mut outcomes = Vec::new();
    let (dtypes, cases_per_type): (&[FloatDType], usize) = match options.scope {
        StressScope::Device => (&[FloatDType::F32], 1),
        StressScope::Bounded | StressScope::Full => (&[FloatDType::F32, FloatDType::F16, FloatDType::BF16], usize::MAX),
    };
    for &dtype in dtypes {
        let reduced = dtype != FloatDType::F32;
        let cases: Vec<&NetworkCase> =
            network_cases.iter().filter(|case| !reduced || case.4).take(cases_per_type).collect();
        let suffix = if reduced { format!(", {}", dtype_name(dtype)) } else { String::new() };
        if reduced && !device.supports_dtype(dtype) {
            for &&(name, size, inputs, _, _) in &cases {
                let reason = format!("the device lacks {}", dtype_name(dtype));
                outcomes.push(skipped_case("network", format!("{name} ({inputs} at {size}{suffix})"), reason));
            }
            continue;
        }
        let model = model.clone().with_float_dtype(dtype);
        for (index, &&(name, size, inputs, setup, _)) in cases.iter().enumerate() {
            let (model, objective, render) = (&model, &network_objective, &network_render);
            outcomes.push(run_case(Case {
                group: "network",
                name: format!("{name} ({inputs} at {size}{suffix})"),
                expect: Expect::Finite,
                run: Box::new(move |probe| {
                    let mut scenario = Scenario::new(size, inputs, 2, 100 + index as u64);
                    setup(&mut scenario);
                    network::run(probe, &scenario, model, objective, render, device)
                }),
            }));
        }
    }
    Ok(outcomes)
}
