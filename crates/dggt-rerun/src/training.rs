//! A training run shown live in rerun: `dggt train --rerun FILE.rrd` (a recording that grows as the run goes)
//! or `--rerun-connect URL` (a running viewer), on a `step` time line.
//!
//! Entities: `train/loss`, `train/target_psnr`, `train/grad_norm`, `train/learning_rate`, `train/step_seconds`
//! and `train/terms/NAME` (each step's scalars, as `metrics.jsonl` has them); `validation/scores/{psnr, ssim,
//! lpips, d_rmse}` at each validation pass; with a snapshot, `validation/fFFF_cC/{render, truth, difference,
//! depth}` per target view, `world/predicted/fFFF_cC` (the camera the network placed, its pinhole, `image`,
//! `depth` and `dynamic`) and `world/export/fFFF_cC` (the export's camera) per input view, and
//! `world/gaussians` (the window's Gaussians as splats). Steps are the values `metrics.jsonl` records (a
//! training step by its index from 0, a validation pass by the steps trained before it); the world is the
//! snapshot's (see `dggt_train::watch`).
//!
//! The run never waits for the recording: the trainer hands each message to a queue of [`QUEUE`] and drops it,
//! with a warning, when the queue is full; a thread of its own logs them. After each validation pass that
//! thread flushes (the file then holds the run up to that pass); when the viewer went away the flush fails, the
//! thread says so once and drops the rest.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::time::{Duration, Instant};

use dggt_train::config::ViewerSection;
use dggt_train::records::LoggedStep;
use dggt_train::validate::Validation;
use dggt_train::{RunWatcher, SnapshotOptions, ValidationSnapshot};

use crate::components::{camera_transform, depth_image, pinhole};
use crate::error::RerunError;
use crate::splats::splats;

/// Messages waiting for the recording thread; beyond them the run drops what it would log.
pub const QUEUE: usize = 256;
/// How long the recording thread waits for a flush after a validation pass before moving on.
const FLUSH_WAIT: Duration = Duration::from_secs(2);
/// How long the end of the run waits for what is queued to be written or sent.
const FINISH_WAIT: Duration = Duration::from_secs(20);

/// Where a training recording goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Destination {
    /// A new `.rrd` file.
    File(PathBuf),
    /// A viewer's gRPC proxy (`rerun+http://HOST:PORT/proxy`).
    Viewer(String),
}

impl std::fmt::Display for Destination {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::File(path) => write!(f, "{}", path.display()),
            Self::Viewer(url) => write!(f, "the viewer at {url}"),
        }
    }
}

/// What a finished recording holds.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingRecordingReport {
    pub destination: Destination,
    /// Steps and validation passes logged.
    pub steps: u64,
    pub validations: u64,
    /// Messages the run dropped because the recording fell behind.
    pub dropped: u64,
    /// Why the recording stopped before the run's end, when it did (the viewer went away, say).
    pub lost: Option<String>,
    /// The file's size, for a file.
    pub bytes: Option<u64>,
}

impl TrainingRecordingReport {
    /// `recording: runs/x.rrd (1.2 MB; 300 steps, 4 validation passes)` and what was lost.
    pub fn line(&self) -> String {
        let size = self.bytes.map_or(String::new(), |b| format!("{:.1} MB; ", b as f64 / 1e6));
        let mut line = format!(
            "recording: {} ({size}{} steps, {} validation passes)",
            self.destination, self.steps, self.validations
        );
        if self.dropped > 0 {
            line += &format!("; {} messages dropped while it fell behind", self.dropped);
        }
        if let Some(lost) = &self.lost {
            line += &format!("; stopped early: {lost}");
        }
        line
    }
}

/// The run's side of a training recording: a [`RunWatcher`] that queues what it is shown for the recording
/// thread.
pub struct TrainingRecording {
    destination: Destination,
    queue: SyncSender<Message>,
    done: Receiver<WorkerReport>,
    settings: ViewerSection,
    /// The configuration's peak learning rate (`optim.lr`), which the schedule's factor scales.
    peak_lr: f64,
    validations_seen: u64,
    dropped: u64,
}

enum Message {
    Step { step: u64, scalars: Vec<(String, f64)> },
    Validation { step: u64, scores: Vec<(&'static str, f64)>, snapshot: Option<Arc<ValidationSnapshot>> },
    Finish,
}

#[derive(Debug, Default)]
struct WorkerReport {
    steps: u64,
    validations: u64,
    lost: Option<String>,
}

impl TrainingRecording {
    /// Opens the recording at `destination` (a file is created; a viewer is connected to in the background)
    /// with a layout showing `views` (`(frame, camera)` positions of the validation targets).
    pub fn start(
        destination: Destination,
        views: &[(usize, usize)],
        settings: ViewerSection,
        peak_lr: f64,
    ) -> Result<Self, RerunError> {
        let builder = rerun::RecordingStreamBuilder::new("dggt_training").with_blueprint(layout(views));
        let opened = match &destination {
            Destination::File(path) => builder.save(path),
            Destination::Viewer(url) => builder.connect_grpc_opts(url.clone()),
        };
        let recording = opened.map_err(|e| opening_error(&destination, &e))?;
        recording.log_static("world", &rerun::ViewCoordinates::RDF()).map_err(|e| opening_error(&destination, &e))?;
        let (queue, messages) = mpsc::sync_channel(QUEUE);
        let (report, done) = mpsc::channel();
        let name = destination.to_string();
        std::thread::Builder::new()
            .name("rerun-recording".into())
            .spawn(move || {
                let worker = log_messages(&recording, &name, messages);
                report.send(worker).ok();
            })
            .map_err(|e| opening_error(&destination, &e))?;
        Ok(Self { destination, queue, done, settings, peak_lr, validations_seen: 0, dropped: 0 })
    }

    /// Waits (at most [`FINISH_WAIT`]) for what is queued to be logged and flushed; returns what was recorded.
    pub fn finish(self) -> TrainingRecordingReport {
        let deadline = Instant::now() + FINISH_WAIT;
        let mut finish = Message::Finish;
        while let Err(TrySendError::Full(message)) = self.queue.try_send(finish) {
            if Instant::now() >= deadline {
                break;
            }
            finish = message;
            std::thread::sleep(Duration::from_millis(20));
        }
        let worker = self.done.recv_timeout(deadline.saturating_duration_since(Instant::now())).unwrap_or_else(|_| {
            WorkerReport {
                lost: Some(format!("not all was written within {} s", FINISH_WAIT.as_secs())),
                ..Default::default()
            }
        });
        if let Some(lost) = &worker.lost {
            tracing::warn!("rerun recording to {}: {lost}", self.destination);
        }
        let bytes = match &self.destination {
            Destination::File(path) => std::fs::metadata(path).ok().map(|m| m.len()),
            Destination::Viewer(_) => None,
        };
        TrainingRecordingReport {
            destination: self.destination.clone(),
            steps: worker.steps,
            validations: worker.validations,
            dropped: self.dropped,
            lost: worker.lost,
            bytes,
        }
    }

    /// Queues `message`, or drops it (warning at the first drop) when the recording thread is behind or gone.
    fn queue(&mut self, message: Message) {
        match self.queue.try_send(message) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                if self.dropped == 0 {
                    tracing::warn!(
                        "rerun recording to {} falls behind the run: what it cannot take is dropped (the run goes on)",
                        self.destination
                    );
                }
                self.dropped += 1;
            }
            Err(TrySendError::Disconnected(_)) => self.dropped += 1,
        }
    }
}

impl RunWatcher for TrainingRecording {
    fn step(&mut self, step: &LoggedStep<'_>) {
        let record = step.record;
        if !record.step.is_multiple_of(self.settings.scalars_every) {
            return;
        }
        let mut scalars = vec![
            ("learning_rate".to_owned(), record.lr_factor * self.peak_lr),
            ("step_seconds".to_owned(), record.step_s),
        ];
        if let Some(update) = &record.update {
            scalars.push(("grad_norm".into(), update.grad_norm));
        }
        if let Some(measures) = &record.measures {
            scalars.push(("loss".into(), measures.loss));
            scalars.push(("target_psnr".into(), measures.target_psnr));
            scalars.extend(measures.terms.iter().map(|(name, value)| (format!("terms/{name}"), *value)));
        }
        self.queue(Message::Step { step: record.step, scalars });
    }

    fn snapshot_wanted(&self, _step: u64) -> Option<SnapshotOptions> {
        let every = self.settings.snapshot_every;
        (every > 0 && self.validations_seen.is_multiple_of(every))
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
        let scores = scores.into_iter().filter_map(|(name, value)| Some((name, value?))).collect();
        self.queue(Message::Validation { step, scores, snapshot: validation.snapshot.clone() });
    }
}

/// The recording thread: logs every message until [`Message::Finish`] (or the run's side is gone), flushing
/// after each validation pass; stops logging, once, when a flush fails.
fn log_messages(recording: &rerun::RecordingStream, destination: &str, messages: Receiver<Message>) -> WorkerReport {
    let mut report = WorkerReport::default();
    let mut warned = false;
    for message in messages {
        if matches!(message, Message::Finish) {
            break;
        }
        if report.lost.is_some() {
            continue;
        }
        let logged = match message {
            Message::Step { step, scalars } => {
                report.steps += 1;
                log_step(recording, step, &scalars)
            }
            Message::Validation { step, scores, snapshot } => {
                report.validations += 1;
                let logged = log_validation(recording, step, &scores, snapshot.as_deref());
                if let Err(rerun::sink::SinkFlushError::Failed { message }) = recording.flush_with_timeout(FLUSH_WAIT) {
                    tracing::warn!("rerun recording to {destination} stopped: {message} (the run goes on)");
                    report.lost = Some(message);
                }
                logged
            }
            Message::Finish => Ok(()),
        };
        if let Err(error) = logged
            && !warned
        {
            tracing::warn!("rerun recording to {destination}: {error} (the rest is still logged)");
            warned = true;
        }
    }
    if report.lost.is_none()
        && let Err(rerun::sink::SinkFlushError::Failed { message }) = recording.flush_with_timeout(FINISH_WAIT)
    {
        report.lost = Some(message);
    }
    report
}

fn log_step(recording: &rerun::RecordingStream, step: u64, scalars: &[(String, f64)]) -> Result<(), RerunError> {
    recording.set_time_sequence("step", step as i64);
    for (name, value) in scalars.iter().filter(|(_, value)| value.is_finite()) {
        send(recording, &format!("train/{name}"), &rerun::Scalars::new([*value]))?;
    }
    Ok(())
}

fn log_validation(
    recording: &rerun::RecordingStream,
    step: u64,
    scores: &[(&str, f64)],
    snapshot: Option<&ValidationSnapshot>,
) -> Result<(), RerunError> {
    recording.set_time_sequence("step", step as i64);
    for (name, value) in scores.iter().filter(|(_, value)| value.is_finite()) {
        send(recording, &format!("validation/scores/{name}"), &rerun::Scalars::new([*value]))?;
    }
    let Some(snapshot) = snapshot else { return Ok(()) };
    for target in &snapshot.targets {
        let entity = view_entity("validation", target.frame, target.camera);
        send(recording, &format!("{entity}/render"), &rgb8(&target.render))?;
        send(recording, &format!("{entity}/truth"), &rgb8(&target.truth))?;
        send(recording, &format!("{entity}/difference"), &rgb8(&target.difference))?;
        send(recording, &format!("{entity}/depth"), &depth_image(target.depth.size, &target.depth.depths))?;
    }
    for input in &snapshot.inputs {
        let size = input.depth.size;
        let predicted = view_entity("world/predicted", input.frame, input.camera);
        send(recording, &predicted, &camera_transform(&input.predicted.world_from_camera))?;
        send(recording, &predicted, &pinhole(&input.predicted.intrinsics, size))?;
        send(recording, &format!("{predicted}/image"), &rgb8(&input.image))?;
        send(recording, &format!("{predicted}/depth"), &depth_image(size, &input.depth.depths))?;
        if let Some(dynamic) = &input.dynamic {
            let grey = rerun::Image::from_l8(dynamic.as_raw().clone(), [dynamic.width(), dynamic.height()]);
            send(recording, &format!("{predicted}/dynamic"), &grey)?;
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

fn rgb8(image: &image::RgbImage) -> rerun::Image {
    rerun::Image::from_rgb24(image.as_raw().clone(), [image.width(), image.height()])
}

fn send(recording: &rerun::RecordingStream, entity: &str, data: &impl rerun::AsComponents) -> Result<(), RerunError> {
    recording.log(entity, data).map_err(|e| RerunError::Entity { entity: entity.into(), detail: e.to_string() })
}

fn opening_error(destination: &Destination, error: &dyn std::fmt::Display) -> RerunError {
    RerunError::Opening { destination: destination.to_string(), detail: error.to_string() }
}

/// The layout: the losses and the validation scores over the steps, the 3D window (cameras, depth, splats),
/// and per validation target tabs of its render, truth, difference and depth.
fn layout(views: &[(usize, usize)]) -> rerun::blueprint::Blueprint {
    use rerun::blueprint::{
        Blueprint, ContainerLike, Grid, Horizontal, Spatial2DView, Spatial3DView, Tabs, TimeSeriesView, Vertical,
    };
    let losses: ContainerLike = TimeSeriesView::new("losses").with_origin("train").into();
    let scores: ContainerLike = TimeSeriesView::new("validation scores").with_origin("validation/scores").into();
    let scene: ContainerLike = Spatial3DView::new("validation window").with_origin("world").into();
    let view_tabs = |&(frame, camera): &(usize, usize)| -> ContainerLike {
        let origin = view_entity("validation", frame, camera);
        let tab = |part: &str| -> ContainerLike {
            Spatial2DView::new(format!("frame {frame} camera {camera}: {part}"))
                .with_origin(origin.clone())
                .with_contents([format!("$origin/{part}")])
                .into()
        };
        Tabs::new(["render", "truth", "difference", "depth"].map(tab)).into()
    };
    let renders: ContainerLike = Grid::new(views.iter().map(view_tabs)).into();
    let curves: ContainerLike = Vertical::new([losses, scores]).into();
    Blueprint::new(Horizontal::new([curves, scene, renders]).with_column_shares([1.0, 2.0, 2.0]))
}
