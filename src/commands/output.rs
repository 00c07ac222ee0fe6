//! The output folder (`--out`) of every command that writes one: a command writes into a new or empty folder,
//! so that the files of two runs never mix. Told to (`--overwrite`), it replaces an earlier output of the same
//! command: the folder's whole content is removed first, and only from a folder that holds that command's
//! output, so a mistyped `--out` never empties a folder of anything else.

use std::path::Path;

use anyhow::{Context, Result, bail};

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
