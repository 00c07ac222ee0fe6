//! A DGGT training run shown live (`dggt train --rerun FILE.rrd` or `--rerun-connect URL`) on the `step` time
//! line, through a [`LiveRecording`] (which never makes the run wait).
//!
//! Entities: `train/loss`, `train/target_psnr`, `train/grad_norm`, `train/learning_rate`, `train/step_seconds`
//! and `train/terms/NAME` (each step's scalars, as `metrics.jsonl` has them); `validation/scores/{psnr, ssim,
//! lpips, d_rmse}` at each validation pass; with a snapshot, `validation/fFFF_cC/{render, truth, difference,
//! depth}` per target view, `world/predicted/fFFF_cC` (the camera the network placed, its pinhole and `image`),
//! `world/export/fFFF_cC` (the export's camera) and `validation/inputs/fFFF_cC/{depth, dynamic}` (the network's
//! depth and dynamic probability) per input view, and
//! `world/gaussians` (the window's Gaussians as splats). Steps are the values `metrics.jsonl` records (a
//! training step by its index from 0, a validation pass by the steps trained before it); the world is the
//! snapshot's (see `dggt_train::snapshot`).

use dggt_train::config::ViewerSection;
use dggt_train::records::LoggedStep;
use dggt_train::validate::Validation;
use dggt_train::{RunWatcher, SnapshotOptions, ValidationSnapshot, ValidationViews};

use crate::components::{camera_transform, depth_image, grey8_image, part_tabs, pinhole, rgb8_image};
use crate::error::RerunError;
use crate::live::{Destination, LiveRecording, LiveReport, scalars, send};
use crate::splats::splats;

/// A DGGT run's live recording: a [`RunWatcher`] that queues what it is shown.
pub struct TrainingRecording {
    live: LiveRecording,
    settings: ViewerSection,
    /// The configuration's peak learning rate (`optim.lr`), which the schedule's factor scales.
    peak_lr: f64,
    validations_seen: u64,
}

impl TrainingRecording {
    /// Opens the recording at `destination` with a layout showing `views`.
    pub fn start(
        destination: Destination,
        views: &ValidationViews,
        settings: ViewerSection,
        peak_lr: f64,
    ) -> Result<Self, RerunError> {
        let live = LiveRecording::start(destination, "dggt_training", layout(views))?;
        Ok(Self { live, settings, peak_lr, validations_seen: 0 })
    }

    /// Waits for what is queued; returns what was recorded.
    pub fn finish(self) -> LiveReport {
        self.live.finish()
    }
}

impl RunWatcher for TrainingRecording {
    fn step(&mut self, step: &LoggedStep<'_>) {
        let record = step.record;
        if !record.step.is_multiple_of(self.settings.scalars_every) {
            return;
        }
        let mut values = vec![
            ("learning_rate".to_owned(), record.lr_factor * self.peak_lr),
            ("step_seconds".to_owned(), record.step_s),
        ];
        if let Some(update) = &record.update {
            values.push(("grad_norm".into(), update.grad_norm));
        }
        if let Some(measures) = &record.measures {
            values.push(("loss".into(), measures.loss));
            values.push(("target_psnr".into(), measures.target_psnr));
            values.extend(measures.terms.iter().map(|(name, value)| (format!("terms/{name}"), *value)));
        }
        self.live.step(record.step, scalars("train", values));
    }

    fn snapshot_wanted(&self, _step: u64) -> Option<SnapshotOptions> {
        self.settings
            .pictures_pass(self.validations_seen)
            .then_some(SnapshotOptions { max_splats: self.settings.max_splats })
    }

    fn validation(&mut self, step: u64, validation: &Validation) {
        self.validations_seen += 1;
        let scores = [
            ("psnr", Some(validation.psnr)),
            ("ssim", Some(validation.ssim)),
            ("lpips", validation.lpips),
            ("d_rmse", validation.d_rmse),
        ];
        let scores = scores.into_iter().filter_map(|(name, value)| Some((name.to_owned(), value?))).collect();
        let log_scores = scalars("validation/scores", scores);
        let snapshot = validation.snapshot.clone();
        self.live.validation(
            step,
            Box::new(move |recording| {
                log_scores(recording)?;
                match snapshot {
                    Some(snapshot) => log_snapshot(recording, &snapshot),
                    None => Ok(()),
                }
            }),
        );
    }
}

fn log_snapshot(recording: &rerun::RecordingStream, snapshot: &ValidationSnapshot) -> Result<(), RerunError> {
    recording
        .log_static("world", &rerun::ViewCoordinates::RDF())
        .map_err(|e| RerunError::Entity { entity: "world".into(), detail: e.to_string() })?;
    for target in &snapshot.targets {
        let entity = view_entity("validation", target.frame, target.camera);
        send(recording, &format!("{entity}/render"), &rgb8_image(&target.render))?;
        send(recording, &format!("{entity}/truth"), &rgb8_image(&target.truth))?;
        send(recording, &format!("{entity}/difference"), &rgb8_image(&target.difference))?;
        send(recording, &format!("{entity}/depth"), &depth_image(target.depth.size, &target.depth.depths))?;
    }
    for input in &snapshot.inputs {
        let size = input.depth.size;
        let predicted = view_entity("world/predicted", input.frame, input.camera);
        send(recording, &predicted, &camera_transform(&input.predicted.world_from_camera))?;
        send(recording, &predicted, &pinhole(&input.predicted.intrinsics, size))?;
        send(recording, &format!("{predicted}/image"), &rgb8_image(&input.image))?;
        let outputs = view_entity("validation/inputs", input.frame, input.camera);
        send(recording, &format!("{outputs}/depth"), &depth_image(size, &input.depth.depths))?;
        if let Some(dynamic) = &input.dynamic {
            send(recording, &format!("{outputs}/dynamic"), &grey8_image(dynamic))?;
        }
        let export = view_entity("world/export", input.frame, input.camera);
        send(recording, &export, &camera_transform(&input.export.world_from_camera))?;
        send(recording, &export, &pinhole(&input.export.intrinsics, size))?;
    }
    if !snapshot.gaussians.is_empty() {
        send(recording, "world/gaussians", &splats(&snapshot.gaussians))?;
    }
    Ok(())
}

/// `PREFIX/fFFF_cC`: a view by its frame and camera positions.
fn view_entity(prefix: &str, frame: usize, camera: usize) -> String {
    format!("{prefix}/f{frame:03}_c{camera}")
}

/// The layout: the losses and the validation scores over the steps; the 3D window (cameras, images, splats)
/// above the input views' depth and dynamic masks; per validation target, tabs of its render, truth, difference
/// and depth.
fn layout(views: &ValidationViews) -> rerun::blueprint::Blueprint {
    use rerun::blueprint::{Blueprint, ContainerLike, Grid, Horizontal, Spatial3DView, TimeSeriesView, Vertical};
    let losses: ContainerLike = TimeSeriesView::new("losses").with_origin("train").into();
    let scores: ContainerLike = TimeSeriesView::new("validation scores").with_origin("validation/scores").into();
    let scene: ContainerLike = Spatial3DView::new("validation window").with_origin("world").into();
    let target_tabs = |&(frame, camera): &(usize, usize)| {
        let origin = view_entity("validation", frame, camera);
        part_tabs(&format!("frame {frame} camera {camera}"), &origin, &["render", "truth", "difference", "depth"])
    };
    let input_tabs = |&(frame, camera): &(usize, usize)| {
        let origin = view_entity("validation/inputs", frame, camera);
        part_tabs(&format!("input frame {frame} camera {camera}"), &origin, &["depth", "dynamic"])
    };
    let targets: ContainerLike = Grid::new(views.targets.iter().map(target_tabs)).into();
    let inputs: ContainerLike = Grid::new(views.inputs.iter().map(input_tabs)).into();
    let curves: ContainerLike = Vertical::new([losses, scores]).into();
    let window: ContainerLike = Vertical::new([scene, inputs]).with_row_shares([2.0, 1.0]).into();
    Blueprint::new(Horizontal::new([curves, window, targets]).with_column_shares([1.0, 2.0, 2.0]))
}
