//! `dggt`: feedforward 4D reconstruction of dynamic driving scenes — the command-line entry point. Each
//! subcommand lives in [`commands`]; [`backend`] turns `--device` into burn devices; [`failure`] says what went
//! wrong when a command fails.

mod backend;
mod commands;
mod failure;

use std::io::IsTerminal;
use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};
use tracing_subscriber::EnvFilter;

use crate::commands::{
    bench, convert, curves, devices, edit, eval, inspect, parity, reconstruct, refine, refine_pairs, refine_train,
    stress, synth, train,
};

#[derive(Debug, Parser)]
#[command(name = "dggt", version, about = "Feedforward 4D reconstruction of dynamic driving scenes")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The commands; parsed once per process, so the size of the largest arguments does not matter.
#[derive(Debug, Subcommand)]
#[allow(clippy::large_enum_variant)]
enum Command {
    Synth(synth::Args),
    Convert(convert::Args),
    Inspect(inspect::Args),
    Parity(parity::Args),
    Train(train::Args),
    Reconstruct(reconstruct::Args),
    Edit(edit::Args),
    RefinePairs(refine_pairs::Args),
    RefineTrain(refine_train::Args),
    Stress(stress::Args),
    Eval(eval::Args),
    Bench(bench::Args),
    Curves(curves::Args),
    Devices(devices::Args),
    Refine(refine::Args),
}

fn main() -> ExitCode {
    init_logging();
    match run(Cli::parse().command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("{}", failure::describe(&error, failure::Backtraces::from_env()));
            ExitCode::FAILURE
        }
    }
}

/// Log lines on stderr, at the level `RUST_LOG` names (info by default), coloured only on a terminal and
/// without `NO_COLOR`, so that a log written to a file or a pipe holds no colour codes.
fn init_logging() {
    let no_color = std::env::var_os("NO_COLOR").is_some_and(|value| !value.is_empty());
    tracing_subscriber::fmt()
        .with_env_filter(EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")))
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal() && !no_color)
        .init();
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Synth(args) => synth::run(args),
        Command::Convert(args) => convert::run(args),
        Command::Inspect(args) => inspect::run(args),
        Command::Parity(args) => parity::run(args),
        Command::Train(args) => train::run(args),
        Command::Reconstruct(args) => reconstruct::run(args),
        Command::Edit(args) => edit::run(args),
        Command::RefinePairs(args) => refine_pairs::run(&args),
        Command::RefineTrain(args) => refine_train::run(args),
        Command::Stress(args) => stress::run(args),
        Command::Eval(args) => eval::run(&args),
        Command::Bench(args) => bench::run(args),
        Command::Curves(args) => curves::run(args),
        Command::Devices(args) => devices::run(&args),
        Command::Refine(args) => refine::run(args),
    }
}
