//! The subcommands of `dggt`, one module each: its arguments, their translation into the library's options,
//! and what it prints. The libraries know nothing of the command line.

pub mod bench;
pub mod bench_compute;
pub mod bench_refiner;
pub mod convert;
pub mod curves;
pub mod devices;
pub mod edit;
pub mod eval;
pub mod inspect;
pub mod output;
pub mod parity;
pub mod reconstruct;
pub mod refine;
pub mod refine_pairs;
pub mod refine_train;
pub mod render_output;
pub mod stress;
pub mod synth;
pub mod train;
pub mod viewer;

use std::ops::Range;

/// Parses `START..END` (end exclusive, not empty), the form every `--frames` takes.
pub(crate) fn parse_range(text: &str) -> Result<Range<usize>, String> {
    let (start, end) = text.split_once("..").ok_or_else(|| format!("expected START..END, got {text:?}"))?;
    let start: usize = start.trim().parse().map_err(|_| format!("bad range start in {text:?}"))?;
    let end: usize = end.trim().parse().map_err(|_| format!("bad range end in {text:?}"))?;
    if end <= start {
        return Err(format!("empty range {text:?}"));
    }
    Ok(start..end)
}
