//! The suite's files: `compute.json` (every record) and a Markdown table that drops into
//! `docs/BENCHMARKS.md`, with the reference implementations' figures for the same work beside ours and the
//! advantage: reference time / our time (above 1: we are faster), our frames / reference frames for the
//! longest sequence (above 1: we fit more).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::Record;
use crate::error::BenchError;

/// The contents of `compute.json`, and of a reference's file (`scripts/reference_bench.py --out`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordFile {
    #[serde(default)]
    pub implementation: String,
    /// The device, in words.
    #[serde(default)]
    pub device: String,
    /// How the implementation was built where that matters (ours: with or without burn's fusion and autotune).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub build: String,
    pub records: Vec<Record>,
}

impl RecordFile {
    pub fn read(path: &Path) -> Result<Self, BenchError> {
        let text = std::fs::read_to_string(path).map_err(|e| BenchError::file(path, e))?;
        serde_json::from_str(&text).map_err(|e| BenchError::file(path, format!("not a record file: {e}")))
    }

    /// One file of several runs' records of the same implementation (e.g. a suite run in parts): a later
    /// record of a key replaces an earlier one; the devices are listed once each.
    pub fn merge(files: Vec<RecordFile>) -> Result<Self, BenchError> {
        let mut merged =
            RecordFile { implementation: String::new(), device: String::new(), build: String::new(), records: vec![] };
        for (index, file) in files.into_iter().enumerate() {
            if index == 0 {
                merged.implementation = file.implementation.clone();
                merged.build = file.build.clone();
            } else if (&file.implementation, &file.build) != (&merged.implementation, &merged.build) {
                return Err(BenchError::MixedRecords {
                    first: format!("{} ({})", merged.implementation, merged.build),
                    other: format!("{} ({})", file.implementation, file.build),
                });
            }
            if !merged.device.split("; ").any(|device| device == file.device) {
                if !merged.device.is_empty() {
                    merged.device.push_str("; ");
                }
                merged.device.push_str(&file.device);
            }
            for record in file.records {
                merged.records.retain(|kept| kept.key != record.key);
                merged.records.push(record);
            }
        }
        Ok(merged)
    }

    pub fn write(&self, path: &Path) -> Result<(), BenchError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| BenchError::file(path, e))?;
        crate::report::write_text(path, &text)
    }
}

/// The Markdown table of `ours` with, per key, the first reference record of that key; with a `baseline` (our
/// own records of another build, e.g. without fusion and autotune), its figures and ours' gain over it too.
/// Every key of any file gets a row: ours first, then the baseline's, then the references' (`—` where ours has
/// none).
pub fn markdown(ours: &RecordFile, baseline: Option<&RecordFile>, references: &[RecordFile]) -> String {
    let mut text = format!("Device: {}\n\n", ours.device);
    if !ours.build.is_empty() {
        text.push_str(&format!("dggt-rs build: {}\n\n", ours.build));
    }
    if let Some(baseline) = baseline {
        text.push_str(&format!("Baseline: dggt-rs, {} ({})\n\n", baseline.build, baseline.device));
    }
    for file in references {
        text.push_str(&format!("Reference `{}`: {}\n\n", file.implementation, file.device));
    }
    let (baseline_headers, baseline_rule) =
        if baseline.is_some() { (" baseline | gain |", "---:|---:|") } else { ("", "") };
    text.push_str(&format!("| work | dggt-rs | MiB |{baseline_headers} reference | MiB | advantage | notes |\n"));
    text.push_str(&format!("|---|---:|---:|{baseline_rule}---|---:|---:|---|\n"));
    let ours_records: Vec<&Record> = ours.records.iter().collect();
    let baseline_records: Vec<&Record> = baseline.map(|file| file.records.iter().collect()).unwrap_or_default();
    let reference_records: Vec<&Record> = references.iter().flat_map(|file| &file.records).collect();
    let mut keys: Vec<&str> = Vec::new();
    for record in ours_records.iter().chain(&baseline_records).chain(&reference_records) {
        if !keys.contains(&record.key.as_str()) {
            keys.push(&record.key);
        }
    }
    for key in keys {
        let ours = find(&ours_records, key);
        let before = baseline.map(|_| find(&baseline_records, key));
        text.push_str(&row(key, ours, before, find(&reference_records, key)));
    }
    text
}

fn find<'a>(records: &[&'a Record], key: &str) -> Option<&'a Record> {
    records.iter().find(|r| r.key == key).copied()
}

/// One row: ours (`—` when we have no record of the key), then (when a baseline file is given) the baseline's
/// figure and our gain over it, then the reference's with our advantage.
fn row(key: &str, ours: Option<&Record>, baseline: Option<Option<&Record>>, reference: Option<&Record>) -> String {
    let ratio = |other: &Record| match ours.and_then(|ours| advantage(ours, other)) {
        Some(ratio) => format!("{ratio:.2}x"),
        None => String::new(),
    };
    let baseline_cells = match baseline {
        None => String::new(),
        Some(None) => " | |".into(),
        Some(Some(before)) => format!(" {} | {} |", value(before), ratio(before)),
    };
    let (reference_value, reference_mib, advantage, reference_note) = match reference {
        Some(reference) => (
            format!("{} ({})", value(reference), reference.implementation),
            mib(reference),
            ratio(reference),
            if reference.note.is_empty() { String::new() } else { format!("reference: {}", reference.note) },
        ),
        None => (String::new(), String::new(), String::new(), String::new()),
    };
    let first_run = match ours.and_then(|o| o.first_run_ms) {
        Some(ms) => format!("first run (compiling, tuning) {:.1} s", ms / 1e3),
        None => String::new(),
    };
    let notes = [ours.map(|o| o.note.as_str()).unwrap_or_default(), first_run.as_str(), reference_note.as_str()]
        .into_iter()
        .filter(|note| !note.is_empty())
        .collect::<Vec<_>>()
        .join("; ");
    format!(
        "| `{key}` | {} | {} |{baseline_cells} {reference_value} | {reference_mib} | {advantage} | {} |\n",
        ours.map_or("—".into(), value),
        ours.map_or(String::new(), mib),
        cell(&notes)
    )
}

/// Above 1 when we are better: reference time / ours, or our frames / the reference's.
pub fn advantage(ours: &Record, reference: &Record) -> Option<f64> {
    if ours.error.is_some() || reference.error.is_some() {
        return None;
    }
    match (ours.median_ms, reference.median_ms, ours.frames, reference.frames) {
        (Some(ours), Some(reference), ..) if ours > 0.0 => Some(reference / ours),
        (_, _, Some(ours), Some(reference)) if reference > 0 => Some(ours as f64 / reference as f64),
        _ => None,
    }
}

fn value(record: &Record) -> String {
    if let Some(error) = &record.error {
        let short: String = error.lines().next().unwrap_or("").chars().take(80).collect();
        return format!("failed: {}", cell(&short));
    }
    match (record.median_ms, record.frames) {
        (Some(ms), _) if ms >= 1000.0 => format!("{:.2} s", ms / 1000.0),
        (Some(ms), _) => format!("{ms:.1} ms"),
        (None, Some(frames)) => format!("{frames} frames"),
        (None, None) => "—".into(),
    }
}

fn mib(record: &Record) -> String {
    record.peak_mib.map_or(String::new(), |m| format!("{m:.0}"))
}

/// Text safe inside a table cell.
fn cell(text: &str) -> String {
    text.replace('|', "/").replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timed(key: &str, implementation: &str, ms: f64) -> Record {
        Record { median_ms: Some(ms), implementation: implementation.into(), ..Record::new(key) }
    }

    #[test]
    fn the_table_puts_the_reference_beside_ours_with_the_advantage() {
        let ours = RecordFile {
            implementation: "dggt-rs".into(),
            device: "GPU".into(),
            build: String::new(),
            records: vec![
                Record { first_run_ms: Some(12_345.0), ..timed("forward/4/f32", "dggt-rs", 100.0) },
                Record { frames: Some(96), ..Record::new("longest/bf16") },
                Record::failed("raster/10x2/forward", "out of memory | really"),
            ],
        };
        let reference = RecordFile {
            implementation: "reference".into(),
            device: "GPU".into(),
            build: String::new(),
            records: vec![
                timed("forward/4/f32", "release", 250.0),
                Record { frames: Some(48), implementation: "release".into(), ..Record::new("longest/bf16") },
                timed("train-step/4+8/f32", "release+gsplat", 900.0),
            ],
        };
        let table = markdown(&ours, None, &[reference]);
        assert!(table.contains("| `forward/4/f32` | 100.0 ms |  | 250.0 ms (release) |  | 2.50x |"), "{table}");
        assert!(table.contains("| 96 frames |  | 48 frames (release) |  | 2.00x |"), "{table}");
        assert!(table.contains("| first run (compiling, tuning) 12.3 s |"), "{table}");
        assert!(table.contains("failed: out of memory / really"), "{table}");
        assert!(table.contains("| `train-step/4+8/f32` | — |"), "{table}");
    }

    #[test]
    fn a_record_file_round_trips_through_json() {
        let file = RecordFile {
            implementation: "x".into(),
            device: "d".into(),
            build: "b".into(),
            records: vec![timed("k", "x", 1.5)],
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("compute.json");
        file.write(&path).unwrap();
        assert_eq!(RecordFile::read(&path).unwrap(), file);
        std::fs::write(&path, "{").unwrap();
        let error = RecordFile::read(&path).unwrap_err().to_string();
        assert!(error.contains("compute.json") && error.contains("not a record file"), "{error}");
    }

    #[test]
    fn merging_keeps_the_later_record_of_a_key_and_refuses_another_implementation() {
        let first = RecordFile {
            implementation: "dggt-rs".into(),
            device: "GPU".into(),
            build: "fusion + autotune".into(),
            records: vec![timed("forward/4/f32", "dggt-rs", 100.0), timed("raster/1x1/forward", "dggt-rs", 5.0)],
        };
        let second = RecordFile {
            implementation: "dggt-rs".into(),
            device: "GPU".into(),
            build: "fusion + autotune".into(),
            records: vec![timed("forward/4/f32", "dggt-rs", 90.0)],
        };
        let merged = RecordFile::merge(vec![first.clone(), second]).unwrap();
        assert_eq!(merged.device, "GPU");
        let forward: Vec<_> = merged.records.iter().filter(|r| r.key == "forward/4/f32").collect();
        assert_eq!(forward.len(), 1);
        assert_eq!(forward[0].median_ms, Some(90.0));
        assert_eq!(merged.records.len(), 2);
        let other = RecordFile { implementation: "release".into(), ..first.clone() };
        assert!(RecordFile::merge(vec![first.clone(), other]).is_err());
        let untuned = RecordFile { build: "no fusion, no autotune".into(), ..first.clone() };
        let error = RecordFile::merge(vec![first, untuned]).unwrap_err().to_string();
        assert!(error.contains("no fusion, no autotune"), "{error}");
    }

    #[test]
    fn a_baseline_build_shows_beside_ours_with_the_gain() {
        let ours = RecordFile {
            implementation: "dggt-rs".into(),
            device: "GPU".into(),
            build: "fusion + autotune".into(),
            records: vec![timed("forward/4/f32", "dggt-rs", 100.0), timed("raster/1x1/forward", "dggt-rs", 5.0)],
        };
        let baseline = RecordFile {
            build: "no fusion, no autotune".into(),
            records: vec![timed("forward/4/f32", "dggt-rs", 700.0), timed("forward/12/f32", "dggt-rs", 2000.0)],
            ..ours.clone()
        };
        let reference = RecordFile {
            implementation: "reference".into(),
            device: "GPU".into(),
            build: String::new(),
            records: vec![timed("forward/4/f32", "release", 400.0)],
        };
        let table = markdown(&ours, Some(&baseline), &[reference]);
        assert!(table.contains("Baseline: dggt-rs, no fusion, no autotune"), "{table}");
        assert!(
            table.contains("| `forward/4/f32` | 100.0 ms |  | 700.0 ms | 7.00x | 400.0 ms (release) |  | 4.00x |"),
            "{table}"
        );
        assert!(table.contains("| `raster/1x1/forward` | 5.0 ms |  | | | "), "{table}");
        // A key only the baseline measured still has its row.
        assert!(table.contains("| `forward/12/f32` | — |  | 2.00 s |  | "), "{table}");
    }
}
