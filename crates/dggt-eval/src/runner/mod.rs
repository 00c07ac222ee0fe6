//! The evaluation run: scene exports + checkpoint + protocol + device -> per-view records, per-scene and
//! overall means, stage times, written as `eval.json` and `eval.md`.
//!
//! Per scene: the protocol's input frames (all chosen cameras) go through one forward pass (or, with
//! `inputs_per_pass`, overlapping passes of that many inputs: [`crate::Protocol::passes`]) exactly as in
//! `dggt reconstruct` (same preprocessing, chunked heads, predicted cameras; the world is the first input
//! view's camera frame). Every target view is rendered at the release's scene time of its frame: an input
//! view from its own predicted camera, any other from the camera interpolated between the predicted poses of
//! the same rig camera's inputs (`dggt_scene::interpolate_camera`; extrapolated beyond the last input): the
//! paper's unposed protocol. With [`CameraSource::GroundTruth`] the export's poses (relative to the first input
//! view) place the inputs' Gaussians and view every target instead, as a model trained with
//! `render.cameras = "ground_truth"` was trained. Beside every view that is no input, the input view of the
//! same camera nearest in time is scored as it is (the baseline a method must beat to have learnt anything). The
//! render is scored against the export's image preprocessed as the network's inputs are (network
//! resolution), its expected depth against the export's lidar depth ([`crate::grid`],
//! `dggt-metrics`), and the predicted motion against the export's scene flow.
//!
//! Motion: without predicted velocities, dynamic Gaussians are held where they were predicted and the
//! predicted motion of every surface point is zero ([`DynamicMotion::Held`]); its metrics are computed anyway
//! and labelled. With predicted velocities (a motion head, or the Gaussian head's velocity channels) the
//! renders use them, and the expected flow of the surface seen at each lidar cell of an input view is scored
//! in the export's axes and units ([`DynamicMotion::Velocity`], [`crate::motion`]). With
//! `render.dynamic_motion = "instances"` the renders move each object found among the dynamic pixels along its
//! trajectory, and that motion is scored ([`DynamicMotion::Instances`]). Every source the reconstruction has
//! (held; velocities when predicted; instances whenever there is a dynamic head) is also scored at the same
//! cells side by side; at a view between the inputs each source's expected flow is rasterised from the
//! Gaussians assembled its way ([`dggt_scene::render_flow`]). As STORM does, motion is
//! scored at the lidar cells (positive depth; here also not sky and inside the view) and only for windows
//! where some true flow exceeds [`MOTION_GATE`] (STORM skips samples without such motion, whose accuracies
//! would be trivially high).
//!
//! One module per phase, each using only those before it: `stages` (the stopwatch), `setup` (the options,
//! every scene's window checked, LPIPS, the motion source), `forward` (one scene's forward pass and
//! assembly), `views` (a target view's camera, nearest input and rendered flows), `refinement` (the refiner),
//! `cells` and `scoring` (a view scored: its images, then depth and motion at the lidar cells), `outputs`
//! (reports and crops folders), `scene` (one scene's loop over its target views), `passes` (a scene in
//! overlapping passes, joined); this file runs the scenes.

mod cells;
mod forward;
mod outputs;
mod passes;
mod refinement;
mod scene;
mod scoring;
mod setup;
mod stages;
mod views;

use std::time::Instant;

use burn::tensor::Device;
use dggt_data::Scene;
use dggt_infer::load_network;
use dggt_refine::RefinerSpec;
use dggt_run::compute_pool::on_pool_worker;

use crate::error::EvalError;
use crate::report::{EvalReport, summarise_scenes};
use passes::evaluate_in_passes;
use refinement::load_refiner;
use setup::{SceneContext, load_lpips, motion_source};
use stages::{LOAD, Stopwatch};

use crate::grid::DEPTH_EDGE_SPAN;
pub use outputs::write_report;
pub use scene::MOTION_GATE;
pub use scoring::NEAREST_INPUT;
pub use setup::{EvalOptions, LpipsWeights, open_window};

/// Runs the evaluation on `device`, writes `eval.json` and `eval.md` to `options.out` and returns the report. It
/// runs on one of rayon's threads, so that the host kernels' parallel operations keep a share of their work on the
/// calling thread ([`on_pool_worker`]).
pub fn evaluate(options: &EvalOptions, device: &Device) -> Result<EvalReport, EvalError> {
    on_pool_worker(|| evaluate_here(options, device))
}

/// [`evaluate`] on the calling thread.
fn evaluate_here(options: &EvalOptions, device: &Device) -> Result<EvalReport, EvalError> {
    let protocol = &options.protocol;
    protocol.validate()?;
    if options.scenes.is_empty() {
        return Err(EvalError::option("--scene", "give at least one scene export"));
    }
    // Every scene is checked before the network is loaded, so that a bad one fails fast.
    let scenes: Vec<Scene> = options.scenes.iter().map(|root| open_window(root, protocol)).collect::<Result<_, _>>()?;

    let mut total = Stopwatch::default();
    let started = Instant::now();
    let network = load_network(&options.checkpoint, options.architecture.as_ref(), device)?;
    let mut warnings = network.warnings.clone();
    let preprocess = network.input_preprocess(options.width);
    let (lpips, lpips_note) = load_lpips(options, device)?;
    let refiner = load_refiner(options, device)?;
    total.add(LOAD, started);
    if network.model.sky_model.is_none() {
        warnings.push("the network has no sky model: renders have a black sky".into());
    }

    let motion = motion_source(&network);
    let mut reports = Vec::new();
    for (root, scene) in options.scenes.iter().zip(&scenes) {
        tracing::info!("evaluating {}", root.display());
        let context = SceneContext {
            options,
            network: &network,
            preprocess,
            lpips: lpips.as_ref(),
            refiner: refiner.as_ref(),
            motion,
            device,
        };
        let report = evaluate_in_passes(root, scene, protocol, &context).map_err(|e| e.in_scene(root))?;
        total.add_times(&report.stages);
        reports.push(report);
    }
    let splits = protocol.splits();
    let report = EvalReport {
        protocol: protocol.clone(),
        input_frames: protocol.input_frames(),
        checkpoint: network.info,
        preprocess,
        device: format!("{device:?}"),
        motion_source: crate::motion::motion_label(motion).into(),
        poses: options.poses,
        depth_protocol: format!(
            "rendered expected depth vs lidar depth (depth_flows_4, else the lidar sweep binned on the same grid), least-squares scale and shift, at \
                         cells with lidar depth > 0, no sky pixel and the centre (4 col + 2, 4 row + 2) inside the \
                         view, the render read there {sampling}; its AbsRel also split into the cells at a depth edge \
                         (the render's 3x3 neighbourhood spans more than {DEPTH_EDGE_SPAN} in depth) and the rest, under the same \
                         fit; and the median depth (the surface each pixel sees) scored alike under its own fit",
            sampling = options.cell_sampling.describe()
        ),
        motion_protocol: format!(
            "STORM's EPE3D / Acc5 (EPE < 0.05 or relative < 5 %) / Acc10 (EPE < 0.1 or relative < 10 %) / angle \
             (true flow > 0.1) on the export's stored flow at the same cells, in windows with some true flow > \
             {MOTION_GATE}"
        ),
        lpips_note,
        refiner: options.refine.as_ref().map(RefinerSpec::describe),
        overall: summarise_scenes(&reports, &splits),
        scenes: reports,
        stages: total.list(),
        warnings,
    };
    write_report(&report, &options.out)?;
    Ok(report)
}
