//! The output folder (`--out`) of every command that writes one: a command writes into a new or empty folder,
//! so that the files of two runs never mix. Told to (`--overwrite`), it replaces an earlier output of the same
//! command: the folder's whole content is removed first, and only from a folder that holds that command's
//! output, so a mistyped `--out` never empties a folder of anything else. A command that writes one file
//! (`--out FILE`, `--json FILE`) never replaces an existing file unless told to (`--overwrite`). A command whose
//! output grows with its arguments refuses to start when it could write more than a bound (`--max-output-gb`).
//! No other path a command names, its other outputs (`--rerun FILE`) or its inputs, may be the output folder or
//! lie in it: an output there would replace one of the command's own files, and an input there would be removed
//! by `--overwrite` before it is read. A command holds its output while it runs ([`lock`]), and one that
//! writes in stages builds it beside the folder and moves it into place at the end ([`StagedOutput`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use dggt_data::output_lock::OutputLock;
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

/// The output folder of a command that writes one (`--out`) and its `--overwrite` flag.
#[derive(Debug, Clone, clap::Args)]
pub struct OutputFolderArgs {
    /// Output folder; must not exist or be empty.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub overwrite: OverwriteArg,
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
    let entries = check(dir, kind, existing)?;
    for entry in &entries {
        let path = dir.join(entry);
        let removed = if path.is_dir() { std::fs::remove_dir_all(&path) } else { std::fs::remove_file(&path) };
        removed.with_context(|| format!("removing {} to replace the earlier output", path.display()))?;
    }
    if !entries.is_empty() {
        tracing::info!("replaced the earlier `dggt {}` output in {}", kind.command, dir.display());
    }
    Ok(())
}

/// Whether `dir` may take an output of `kind` ([`prepare`]'s rules); the names in it that replacing it removes.
fn check(dir: &Path, kind: OutputKind, existing: Existing) -> Result<Vec<String>> {
    if dir.exists() && !dir.is_dir() {
        bail!("{} is a file: --out takes a folder", dir.display());
    }
    let entries = entries(dir)?;
    if entries.is_empty() {
        return Ok(entries);
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
        Existing::Replace => Ok(entries),
    }
}

/// An output folder written in a staging folder beside it (`.NAME.partial`) and moved into place once complete
/// ([`StagedOutput::finish`]): a command that fails leaves no partial result (dropping it removes the staging
/// folder), and an earlier output it replaces (`--overwrite`, [`prepare`]'s rules) stays until then.
#[derive(Debug)]
pub struct StagedOutput {
    out: PathBuf,
    staging: PathBuf,
    kind: OutputKind,
}

impl StagedOutput {
    /// Checks `out` for an output of `kind` as [`prepare`] does, leaving it as it is, and starts an empty
    /// staging folder (one left by a command that was killed is removed first).
    pub fn begin(out: &Path, kind: OutputKind, existing: Existing) -> Result<Self> {
        check(out, kind, existing)?;
        let resolved = dggt_data::confined::resolved(out).with_context(|| format!("resolving {}", out.display()))?;
        let (Some(parent), Some(name)) = (resolved.parent(), resolved.file_name()) else {
            bail!("{}: --out needs a folder name", out.display());
        };
        let staging = parent.join(format!(".{}.partial", name.to_string_lossy()));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).with_context(|| format!("removing the left {}", staging.display()))?;
        }
        std::fs::create_dir_all(&staging).with_context(|| format!("creating {}", staging.display()))?;
        Ok(Self { out: out.to_path_buf(), staging, kind })
    }

    /// Where the output is written until [`Self::finish`].
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Moves the complete output into place, replacing the folder `begin` accepted there.
    pub fn finish(self) -> Result<()> {
        if self.out.is_dir() {
            std::fs::remove_dir_all(&self.out)
                .with_context(|| format!("removing {} to replace the earlier output", self.out.display()))?;
            tracing::info!("replaced the earlier `dggt {}` output in {}", self.kind.command, self.out.display());
        }
        std::fs::rename(&self.staging, &self.out)
            .with_context(|| format!("moving {} into place as {}", self.staging.display(), self.out.display()))
    }
}

impl Drop for StagedOutput {
    fn drop(&mut self) {
        // After `finish` the staging folder is the output: nothing is left to remove.
        if self.staging.is_dir()
            && let Err(error) = std::fs::remove_dir_all(&self.staging)
        {
            tracing::warn!("cannot remove the unfinished output {}: {error}", self.staging.display());
        }
    }
}

/// Takes the lock of the output `out` (a folder or file) for `command` while the returned guard lives: a second
/// command into the same output is refused at once, naming this one ([`dggt_data::output_lock`]).
pub fn lock(out: &Path, command: &str) -> Result<OutputLock> {
    Ok(OutputLock::acquire(out, command)?)
}

/// Refuses each of `paths` (with the flag that named it) that is the output folder `out` (named by `--out`) or
/// lies in it, naming both; before any work. Links are followed and `..` resolved on both sides.
pub fn refuse_inside_output<'a>(out: &Path, paths: impl IntoIterator<Item = (&'a str, &'a Path)>) -> Result<()> {
    for (flag, path) in paths {
        let inside = dggt_data::confined::is_within(path, out)
            .with_context(|| format!("resolving {flag} {} against --out {}", path.display(), out.display()))?;
        if inside {
            bail!(
                "{flag} {} lies in the output folder --out {}, whose content is this command's own: choose a path \
                 outside it, or another --out",
                path.display(),
                out.display()
            );
        }
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_path_in_or_equal_to_the_output_folder_is_refused_naming_both() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        std::fs::create_dir_all(out.join("images")).unwrap();
        let inside = [out.join("summary.json"), out.clone(), out.join("images/../recording.rrd"), out.join("new/x")];
        for path in &inside {
            let error = refuse_inside_output(&out, [("--rerun", path.as_path())]).unwrap_err().to_string();
            assert!(error.contains(&format!("--rerun {}", path.display())), "{error}");
            assert!(error.contains(&format!("--out {}", out.display())), "{error}");
        }
        let beside = [dir.path().join("recording.rrd"), out.join("../out-2/x.rrd"), dir.path().to_path_buf()];
        for path in &beside {
            refuse_inside_output(&out, [("--rerun", path.as_path())]).unwrap();
        }
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&out, dir.path().join("alias")).unwrap();
            let error = refuse_inside_output(&out, [("--images", dir.path().join("alias/images").as_path())]);
            assert!(error.unwrap_err().to_string().contains("--images"), "a link into the folder is in it");
        }
    }

    /// An output of a test command, recognised by `done.json`.
    const STAGED: OutputKind = OutputKind { command: "test", signature: "done.json" };

    /// A finished staged output holding `done.json` with `text` (and, when given, one more file).
    fn finished(out: &Path, existing: Existing, text: &str, extra: Option<&str>) -> Result<()> {
        let staged = StagedOutput::begin(out, STAGED, existing)?;
        std::fs::write(staged.path().join("done.json"), text).unwrap();
        if let Some(name) = extra {
            std::fs::write(staged.path().join(name), text).unwrap();
        }
        staged.finish()
    }

    #[test]
    fn a_staged_output_is_moved_into_place_when_finished_and_leaves_nothing_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let staged = StagedOutput::begin(&out, STAGED, Existing::Refuse).unwrap();
        std::fs::write(staged.path().join("half.png"), "x").unwrap();
        drop(staged);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "an unfinished output leaves nothing");

        finished(&out, Existing::Refuse, "first", Some("first-only.png")).unwrap();
        assert_eq!(std::fs::read_to_string(out.join("done.json")).unwrap(), "first");
        let error = finished(&out, Existing::Refuse, "second", None).unwrap_err().to_string();
        assert!(error.contains("is not empty") && error.contains("--overwrite"), "{error}");

        let staged = StagedOutput::begin(&out, STAGED, Existing::Replace).unwrap();
        std::fs::write(staged.path().join("done.json"), "second").unwrap();
        assert_eq!(std::fs::read_to_string(out.join("done.json")).unwrap(), "first", "kept until finished");
        drop(staged);
        assert_eq!(std::fs::read_to_string(out.join("done.json")).unwrap(), "first", "kept when it fails");
        finished(&out, Existing::Replace, "second", None).unwrap();
        assert_eq!(std::fs::read_to_string(out.join("done.json")).unwrap(), "second");
        assert!(!out.join("first-only.png").exists(), "nothing of the earlier output stays");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no staging folder left");

        let other = dir.path().join("other");
        std::fs::create_dir_all(&other).unwrap();
        std::fs::write(other.join("notes.txt"), "the user's").unwrap();
        let error = finished(&other, Existing::Replace, "third", None).unwrap_err().to_string();
        assert!(error.contains("holds no earlier `dggt test` output"), "{error}");
        assert_eq!(std::fs::read_to_string(other.join("notes.txt")).unwrap(), "the user's");
    }
}
