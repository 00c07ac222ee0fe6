//! A recording that a run writes while it goes (a file, or a running viewer), on a `step` time line, without
//! ever waiting for it: what the run logs goes to a queue of [`QUEUE`] messages that a thread of its own logs,
//! and is dropped, with one warning, when the queue is full. After each validation pass that thread flushes
//! (the file then holds the run up to that pass); when the viewer went away the flush fails, the thread says so
//! once and drops the rest. [`training`](crate::training) and [`refiner`](crate::refiner) say what each run
//! logs.

use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::time::{Duration, Instant};

use crate::error::RerunError;

/// Messages waiting for the recording thread; beyond them the run drops what it would log.
pub const QUEUE: usize = 256;
/// How long the recording thread waits for a flush after a validation pass before moving on.
const FLUSH_WAIT: Duration = Duration::from_secs(2);
/// How long the end of the run waits for what is queued to be written or sent.
pub const FINISH_WAIT: Duration = Duration::from_secs(20);

/// Where a live recording goes.
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
pub struct LiveReport {
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

impl LiveReport {
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

/// What the recording thread logs at one step.
pub(crate) type Logging = Box<dyn FnOnce(&rerun::RecordingStream) -> Result<(), RerunError> + Send>;

/// Scalars by name (under an entity prefix) as one step's logging; non-finite values are left out.
pub(crate) fn scalars(prefix: &'static str, values: Vec<(String, f64)>) -> Logging {
    Box::new(move |recording| {
        for (name, value) in values.iter().filter(|(_, value)| value.is_finite()) {
            send(recording, &format!("{prefix}/{name}"), &rerun::Scalars::new([*value]))?;
        }
        Ok(())
    })
}

enum Message {
    Step { step: u64, log: Logging },
    Validation { step: u64, log: Logging },
    Finish,
}

#[derive(Debug, Default)]
struct WorkerReport {
    steps: u64,
    validations: u64,
    lost: Option<String>,
}

/// The run's side of a live recording.
pub struct LiveRecording {
    destination: Destination,
    queue: SyncSender<Message>,
    done: Receiver<WorkerReport>,
    dropped: u64,
}

impl LiveRecording {
    /// Opens the recording of application `application` at `destination` (a file is created; a viewer is
    /// connected to in the background) with the layout `blueprint`, its time panel on the `step` line following
    /// the newest step.
    pub(crate) fn start(
        destination: Destination,
        application: &'static str,
        blueprint: rerun::blueprint::Blueprint,
    ) -> Result<Self, RerunError> {
        let opening = |e: &dyn std::fmt::Display| RerunError::Opening {
            destination: destination.to_string(),
            detail: e.to_string(),
        };
        let following = rerun::blueprint::TimePanel::new()
            .with_timeline("step")
            .with_play_state(rerun::blueprint::components::PlayState::Following);
        let builder =
            rerun::RecordingStreamBuilder::new(application).with_blueprint(blueprint.with_time_panel(following));
        let recording = match &destination {
            Destination::File(path) => builder.save(path),
            Destination::Viewer(url) => builder.connect_grpc_opts(url.clone()),
        }
        .map_err(|e| opening(&e))?;
        let (queue, messages) = mpsc::sync_channel(QUEUE);
        let (report, done) = mpsc::channel();
        let name = destination.to_string();
        std::thread::Builder::new()
            .name("rerun-recording".into())
            .spawn(move || {
                report.send(log_messages(&recording, &name, messages)).ok();
            })
            .map_err(|e| opening(&e))?;
        Ok(Self { destination, queue, done, dropped: 0 })
    }

    /// Queues a step's logging.
    pub(crate) fn step(&mut self, step: u64, log: Logging) {
        self.queue(Message::Step { step, log });
    }

    /// Queues a validation pass's logging, after which the recording is flushed.
    pub(crate) fn validation(&mut self, step: u64, log: Logging) {
        self.queue(Message::Validation { step, log });
    }

    /// Waits (at most [`FINISH_WAIT`]) for what is queued to be logged and flushed; returns what was recorded.
    pub fn finish(self) -> LiveReport {
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
            let lost = format!("not all was written within {} s", FINISH_WAIT.as_secs());
            WorkerReport { lost: Some(lost), ..WorkerReport::default() }
        });
        if let Some(lost) = &worker.lost {
            tracing::warn!("rerun recording to {}: {lost}", self.destination);
        }
        let bytes = match &self.destination {
            Destination::File(path) => std::fs::metadata(path).ok().map(|m| m.len()),
            Destination::Viewer(_) => None,
        };
        LiveReport {
            destination: self.destination,
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

/// The recording thread: logs every message until [`Message::Finish`] (or the run's side is gone), flushing
/// after each validation pass; stops logging, once, when a flush fails.
fn log_messages(recording: &rerun::RecordingStream, destination: &str, messages: Receiver<Message>) -> WorkerReport {
    let mut report = WorkerReport::default();
    let mut warned = false;
    for message in messages {
        let (step, log, validation) = match message {
            Message::Finish => break,
            Message::Step { step, log } => (step, log, false),
            Message::Validation { step, log } => (step, log, true),
        };
        if report.lost.is_some() {
            continue;
        }
        recording.set_time_sequence("step", step as i64);
        if let Err(error) = log(recording)
            && !warned
        {
            tracing::warn!("rerun recording to {destination}: {error} (the rest is still logged)");
            warned = true;
        }
        if !validation {
            report.steps += 1;
            continue;
        }
        report.validations += 1;
        if let Err(rerun::sink::SinkFlushError::Failed { message }) = recording.flush_with_timeout(FLUSH_WAIT) {
            tracing::warn!("rerun recording to {destination} stopped: {message} (the run goes on)");
            report.lost = Some(message);
        }
    }
    if report.lost.is_none()
        && let Err(rerun::sink::SinkFlushError::Failed { message }) = recording.flush_with_timeout(FINISH_WAIT)
    {
        report.lost = Some(message);
    }
    report
}

pub(crate) fn send(
    recording: &rerun::RecordingStream,
    entity: &str,
    data: &impl rerun::AsComponents,
) -> Result<(), RerunError> {
    recording.log(entity, data).map_err(|e| RerunError::Entity { entity: entity.into(), detail: e.to_string() })
}
