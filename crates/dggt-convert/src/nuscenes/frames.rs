//! Which readings and boxes make each exported frame of a nuScenes scene.
//!
//! [`FrameRate::KeyFrames`] (drivestudio's default, `--interpolate_N 0`): frame `k` is the scene's `k`-th sample
//! (2 Hz), with its key-frame readings and annotations.
//!
//! [`FrameRate::Interpolated`] (drivestudio's `--interpolate_N N`, `N` in 1..=4; its documentation uses 4, 10 Hz):
//! after each key frame but the last come `N` frames at the times `T_k + j (T_{k+1} - T_k) / (N + 1)` (whole µs),
//! so key frame `k` becomes frame `k (N + 1)`. Every sensor's reading is the one of its channel (walking the
//! `sample_data` `next` chain) nearest that time, so readings may repeat and pixels are never interpolated. An
//! instance annotated at two consecutive key frames gets its box interpolated between them
//! ([`GlobalBox::interpolate`], at the frame's fraction of the interval); between key frames that do not both
//! annotate it, it has no box.

use std::collections::HashMap;

use super::annotations::{GlobalBox, global_boxes};
use super::tables::{SampleDataRow, SampleRow, Tables};
use crate::error::Result;

/// How many frames a nuScenes scene is exported at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrameRate {
    /// The annotated samples only (2 Hz).
    #[default]
    KeyFrames,
    /// `between` (1..=4) frames between consecutive key frames: `2 (between + 1)` Hz.
    Interpolated { between: usize },
}

impl FrameRate {
    /// Frames per key-frame interval.
    fn steps(self) -> usize {
        match self {
            Self::KeyFrames => 1,
            Self::Interpolated { between } => between + 1,
        }
    }

    /// `2 Hz key frames`, `10 Hz (4 between key frames)`.
    pub fn describe(self) -> String {
        match self {
            Self::KeyFrames => "2 Hz key frames".into(),
            Self::Interpolated { between } => format!("{} Hz ({between} between key frames)", 2 * (between + 1)),
        }
    }

    /// The frames exported for a scene of `key_frames` samples.
    pub fn frames(self, key_frames: usize) -> usize {
        key_frames.saturating_sub(1) * self.steps() + key_frames.min(1)
    }
}

/// One exported frame: its time, the reading of every sensor channel, and the boxes.
pub struct PlannedFrame<'a> {
    pub time_us: i64,
    pub readings: HashMap<&'a str, &'a SampleDataRow>,
    pub boxes: Vec<GlobalBox>,
}

/// The frames of a scene whose samples are `samples`, for the sensor `channels`.
pub fn plan<'a>(
    tables: &'a Tables,
    samples: &[&'a SampleRow],
    channels: &[&'a str],
    rate: FrameRate,
) -> Result<Vec<PlannedFrame<'a>>> {
    let boxes = samples.iter().map(|s| global_boxes(tables, s)).collect::<Result<Vec<_>>>()?;
    let mut frames = Vec::new();
    for (k, sample) in samples.iter().enumerate() {
        let readings = channels.iter().map(|&c| Ok((c, tables.key_frame(sample, c)?))).collect::<Result<_>>()?;
        frames.push(PlannedFrame { time_us: sample.timestamp, readings, boxes: boxes[k].clone() });
        let Some(next) = samples.get(k + 1) else { break };
        for j in 1..rate.steps() {
            let fraction = j as f64 / rate.steps() as f64;
            let time_us = sample.timestamp + (next.timestamp - sample.timestamp) * j as i64 / rate.steps() as i64;
            frames.push(PlannedFrame {
                time_us,
                readings: HashMap::new(),
                boxes: between(tables, &boxes[k], &boxes[k + 1], fraction)?,
            });
        }
    }
    if rate != FrameRate::KeyFrames {
        for &channel in channels {
            let chain = tables.channel_chain(tables.key_frame(samples[0], channel)?)?;
            for frame in frames.iter_mut().filter(|f| !f.readings.contains_key(channel)) {
                let nearest =
                    chain.iter().min_by_key(|d| (d.timestamp - frame.time_us).abs()).expect("a chain holds its start");
                frame.readings.insert(channel, nearest);
            }
        }
    }
    Ok(frames)
}

/// The instances annotated at both key frames, interpolated a `fraction` of the way.
fn between(tables: &Tables, earlier: &[GlobalBox], later: &[GlobalBox], fraction: f64) -> Result<Vec<GlobalBox>> {
    let pairs = earlier.iter().filter_map(|a| later.iter().find(|b| b.id == a.id).map(|b| (a, b)));
    pairs
        .map(|(a, b)| {
            a.interpolate(b, fraction).map_err(|e| {
                let table = &tables.instance;
                table.error(&a.id, "annotations whose boxes interpolate", e.to_string())
            })
        })
        .collect()
}
