//! Where an evaluation's outputs go: `eval.json` and `eval.md` in the output folder, and per scene its name in
//! the reports and its folder of crops.

use std::path::{Path, PathBuf};

use super::setup::EvalOptions;
use crate::error::EvalError;
use crate::report::EvalReport;
use crate::sources::CropImages;

/// Writes `eval.json` and `eval.md` to `out`.
pub fn write_report(report: &EvalReport, out: &Path) -> Result<(), EvalError> {
    std::fs::create_dir_all(out).map_err(|e| EvalError::file(out, format!("cannot create the folder: {e}")))?;
    let json = serde_json::to_string_pretty(report).map_err(|e| EvalError::file(out, e.to_string()))?;
    let path = out.join("eval.json");
    std::fs::write(&path, json).map_err(|e| EvalError::file(&path, e.to_string()))?;
    let path = out.join("eval.md");
    std::fs::write(&path, report.markdown()).map_err(|e| EvalError::file(&path, e.to_string()))?;
    Ok(())
}

/// A scene's name in the reports: its folder's name.
pub(super) fn scene_name(root: &Path) -> String {
    root.file_name().map_or_else(|| root.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// The folder of the scene at `root` that its crops are written to, when the options ask for them.
pub(super) fn crops_folder(options: &EvalOptions, root: &Path) -> Option<PathBuf> {
    match options.crops {
        CropImages::Write => Some(options.out.join("crops").join(scene_name(root))),
        CropImages::Skip => None,
    }
}
