//! Converting a long Waymo segment: frames per second and peak memory (the process's high-water mark).
//!
//! The segment is the real five-camera frame (`$DGGT_REAL_DATA` or `../shared/real-data`) repeated with
//! timestamps 0.1 s apart; each copy is decoded and re-encoded with the converter's own messages, so it keeps
//! the fields the converter reads. `DGGT_BENCH_FRAMES` sets its length (default 100).
//!
//! `cargo bench --workspace --features wgpu --bench waymo_segment`

use std::time::Instant;

use dggt_convert::tfrecord::{RecordReader, frame_record};
use dggt_convert::waymo::{WaymoOptions, convert_segment, proto};
use prost::Message;

#[path = "../tests/common/mod.rs"]
mod common;

use common::real_data;

/// The process's peak resident memory in MiB (Linux `VmHWM`).
fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

fn main() {
    let frames: usize = std::env::var("DGGT_BENCH_FRAMES").ok().and_then(|v| v.parse().ok()).unwrap_or(100);
    let mut reader = RecordReader::open(&real_data().join("waymo/one_frame_5cams.tfrecord")).unwrap();
    let (_, payload) = reader.next_record().unwrap().expect("one record");
    let mut frame = proto::decode_frame(payload).unwrap();
    let start_us = frame.timestamp_micros.unwrap();
    let dir = tempfile::tempdir().unwrap();
    let segment = dir.path().join("long.tfrecord");
    let mut file = std::io::BufWriter::new(std::fs::File::create(&segment).unwrap());
    for t in 0..frames {
        frame.timestamp_micros = Some(start_us + 100_000 * t as i64);
        std::io::Write::write_all(&mut file, &frame_record(&frame.encode_to_vec())).unwrap();
    }
    drop(file);
    let bytes = std::fs::metadata(&segment).unwrap().len();
    let before = peak_memory_mib();
    let started = Instant::now();
    let summary = convert_segment(&segment, &dir.path().join("000"), &WaymoOptions::default(), &|_| {}).unwrap();
    let seconds = started.elapsed().as_secs_f64();
    assert_eq!(summary.frames, frames, "every frame of the segment converted");
    println!(
        "waymo segment: {frames} frames ({:.0} MiB) in {seconds:.2} s = {:.1} frames/s; peak memory {:.0} MiB \
         (before converting: {:.0} MiB)",
        bytes as f64 / (1 << 20) as f64,
        frames as f64 / seconds,
        peak_memory_mib().unwrap_or(f64::NAN),
        before.unwrap_or(f64::NAN)
    );
}
