//! The output folder (`--out`) of every command that writes one: a command writes into a new or empty folder,
//! so that the files of two runs never mix. Told to (`--overwrite`), it replaces an earlier output of the same
//! command: the folder's whole content is removed first, and only from a folder that holds that command's
//! output, so a mistyped `--out` never empties a folder of anything else. A command that writes one file
//! (`--out FILE`, `--json FILE`) never replaces an existing file unless told to (`--overwrite`). A command whose
//! output grows with its arguments refuses to start when it could write more than a bound (`--max-output-gb`).

use std::path::Path;

use anyhow::{Context, Result, bail};
use dggt_reconstruct::volume::{DEFAULT_MAX_OUTPUT_BYTES, GB, gigabytes};

/// The `--overwrite` flag of a command that writes an output folder.
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub struct OverwriteArg {
    /// Replace an earlier output of this command in the `--out` folder: everything in the folder is removed
    /// first. Without it, a folder that is not empty is refused.
    #[arg(long)]
    overwrite: bool,
}

impl OverwriteArg {
    /// What the flag asks for.
    pub fn existing(self) -> Existing {
        if self.overwrite { Existing::Replace } else { Existing::Refuse }
    }
}

/// The `--overwrite` flag of a command that writes one file.
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub struct OverwriteFileArg {
    /// Replace the output file when it exists. Without it, an existing file is refused and left as it is.
    #[arg(long)]
    overwrite: bool,
}

impl OverwriteFileArg {
    /// What the flag asks for.
    pub fn existing(self) -> Existing {
        if self.overwrite { Existing::Replace } else { Existing::Refuse }
    }
}

/// What to do with a folder that is not empty.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Existing {
    Refuse,
    /// Empty it, when it holds an earlier output of the same command.
    Replace,
}

/// A command's output: its name, and the file that every output of it holds (written last, as a rule).
#[derive(Debug, Clone, Copy)]
pub struct OutputKind {
    pub command: &'static str,
    pub signature: &'static str,
}

/// Readies `dir` for an output of `kind`: a missing or empty folder as it is; a folder that is not empty
/// emptied when `existing` says to replace and it holds an earlier output of `kind`, refused otherwise.
pub fn prepare(dir: &Path, kind: OutputKind, existing: Existing) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!("{} is a file: --out takes a folder", dir.display());
    }
    let entries = entries(dir)?;
    if entries.is_empty() {
        return Ok(());
    }
    let OutputKind { command, signature } = kind;
    match existing {
        Existing::Refuse => bail!(
            "{} is not empty (it holds {}): choose a new or empty folder with --out, or pass --overwrite to replace \
             an earlier `dggt {command}` output there",
            dir.display(),
            listing(&entries)
        ),
        Existing::Replace if !dir.join(signature).is_file() => bail!(
            "{} holds no earlier `dggt {command}` output (no {signature}), so --overwrite leaves it alone: choose a \
             new or empty folder with --out",
            dir.display()
        ),
        Existing::Replace => {
            for entry in &entries {
                let path = dir.join(entry);
                let removed = if path.is_dir() { std::fs::remove_dir_all(&path) } else { std::fs::remove_file(&path) };
                removed.with_context(|| format!("removing {} to replace the earlier output", path.display()))?;
            }
            tracing::info!("replaced the earlier `dggt {command}` output in {}", dir.display());
            Ok(())
        }
    }
}

/// The names in `dir`, sorted (none when it does not exist).
fn entries(dir: &Path) -> Result<Vec<String>> {
    if !dir.exists() {
        return Ok(Vec::new());
    }
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let entry = entry.with_context(|| format!("reading {}", dir.display()))?;
        names.push(entry.file_name().to_string_lossy().into_owned());
    }
    names.sort();
    Ok(names)
}

/// The first few names, and how many more.
fn listing(names: &[String]) -> String {
    const SHOWN: usize = 3;
    let shown = names.iter().take(SHOWN).cloned().collect::<Vec<_>>().join(", ");
    match names.len().saturating_sub(SHOWN) {
        0 => shown,
        more => format!("{shown} and {more} more"),
    }
}

/// Readies `file` for a command's single output file: a new file as it is; an existing one kept (and the
/// command refused) unless `existing` says to replace it; a folder in its place refused. `flag` is the
/// option that named the file (`--out`, `--json`).
pub fn prepare_file(file: &Path, flag: &str, existing: Existing) -> Result<()> {
    if file.is_dir() {
        bail!("{} is a folder: {flag} takes a file", file.display());
    }
    if file.exists() && existing == Existing::Refuse {
        bail!("{} exists: choose a new file with {flag}, or pass --overwrite to replace it", file.display());
    }
    Ok(())
}

/// The `--max-output-gb` flag of a command whose output grows with its arguments.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct OutputBoundArg {
    /// Refuse to start when the outputs could take more than this many gigabytes (10^9 bytes), estimated
    /// from the arguments before any work.
    #[arg(long, value_name = "GB", default_value_t = DEFAULT_MAX_OUTPUT_BYTES as f64 / GB as f64,
          value_parser = parse_gigabytes)]
    max_output_gb: f64,
}

impl OutputBoundArg {
    /// The bound in bytes.
    pub fn bytes(self) -> u64 {
        (self.max_output_gb * GB as f64) as u64
    }

    /// Refuses an output of `estimated` bytes at most (`what` says what it is made of) over the bound.
    pub fn check(self, estimated: u64, what: &str) -> Result<()> {
        if estimated > self.bytes() {
            bail!(
                "the outputs could take up to {} ({what}), over the bound of {}: ask for less, or raise the bound \
                 with --max-output-gb",
                gigabytes(estimated),
                gigabytes(self.bytes())
            );
        }
        Ok(())
    }
}

fn parse_gigabytes(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(gb) if gb.is_finite() && gb > 0.0 => Ok(gb),
        _ => Err(format!("expected a positive number of gigabytes, got {text:?}")),
    }
}
