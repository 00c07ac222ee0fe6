//! The font of the PNG plots (`bench.png`, `curves.png`). plotters draws text only with a registered font file,
//! and none is shipped: one is looked up at run time (`DGGT_PLOT_FONT`, then the usual system locations, then
//! any `.ttf` under the system font folders) and registered once per process. Without one the plots are drawn
//! without text.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::style::FontStyle;

/// The family name the found font is registered under; text styles name it.
pub const FONT_FAMILY: &str = "sans-serif";

/// Font files tried first, in order.
const FONT_CANDIDATES: [&str; 8] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/truetype/freefont/FreeSans.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "C:\\Windows\\Fonts\\arial.ttf",
];

/// Folders searched (three levels deep) when no candidate exists.
const FONT_FOLDERS: [&str; 3] = ["/usr/share/fonts", "/usr/local/share/fonts", "/Library/Fonts"];

/// Registers a font for plotters once per process; `true` when one was found.
pub fn font_available() -> bool {
    static FOUND: OnceLock<bool> = OnceLock::new();
    *FOUND.get_or_init(|| {
        let mut candidates: Vec<PathBuf> = std::env::var_os("DGGT_PLOT_FONT").map(PathBuf::from).into_iter().collect();
        candidates.extend(FONT_CANDIDATES.iter().map(PathBuf::from));
        for folder in FONT_FOLDERS {
            collect_ttf(Path::new(folder), 3, &mut candidates);
        }
        for path in candidates {
            if let Ok(bytes) = std::fs::read(&path) {
                // plotters keeps registered fonts for the life of the process.
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, bytes).is_ok() {
                    tracing::debug!("plot font: {}", path.display());
                    return true;
                }
            }
        }
        false
    })
}

fn collect_ttf(folder: &Path, depth: usize, into: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(folder) else { return };
    let mut paths: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    paths.sort();
    for path in paths {
        if path.is_dir() && depth > 0 {
            collect_ttf(&path, depth - 1, into);
        } else if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ttf")) {
            into.push(path);
        }
    }
}
