//! `dggt devices`: the compute backends of this build, each checked.

use anyhow::Result;

use crate::backend::{DeviceChoice, self_check};

/// List the compute backends of this build and check that each one computes.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Check only this backend.
    #[arg(long, value_enum)]
    device: Option<DeviceChoice>,
}

pub fn run(args: &Args) -> Result<()> {
    let choices = args.device.map_or(DeviceChoice::ALL.to_vec(), |d| vec![d]);
    let mut failed = false;
    for choice in choices {
        if !choice.compiled() {
            println!("{choice:?}: not in this build (cargo feature `{}`)", choice.feature());
            failed |= args.device.is_some();
            continue;
        }
        match choice.device().and_then(|d| self_check(&d).map(|err| (d, err))) {
            Ok((d, err)) if err < 1e-4 => println!("{choice:?}: ok ({d:?}, matmul error {err:.1e})"),
            Ok((d, err)) => {
                println!("{choice:?}: WRONG RESULTS ({d:?}, matmul error {err:.1e})");
                failed = true;
            }
            Err(e) => {
                println!("{choice:?}: failed: {e:#}");
                failed = true;
            }
        }
    }
    anyhow::ensure!(!failed, "a requested backend is unavailable or computes wrong results");
    Ok(())
}
