//! File writing that never leaves a half-written file behind.

use std::fs;
use std::io::Write;
use std::path::Path;

use crate::error::{DataError, Result};

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, creating parent folders.
/// A crash leaves either the old file or the new one, never a truncated one.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    fs::create_dir_all(parent).map_err(|e| DataError::io(parent, e))?;
    let file_name =
        path.file_name().ok_or_else(|| DataError::Config(format!("{} has no file name", path.display())))?;
    let temporary = parent.join(format!(".{}.partial", file_name.to_string_lossy()));
    let mut file = fs::File::create(&temporary).map_err(|e| DataError::io(&temporary, e))?;
    file.write_all(bytes).map_err(|e| DataError::io(&temporary, e))?;
    file.sync_all().map_err(|e| DataError::io(&temporary, e))?;
    drop(file);
    fs::rename(&temporary, path).map_err(|e| DataError::io(path, e))
}
