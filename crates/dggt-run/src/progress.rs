//! The progress bars of a run, drawn on stderr in one style: the step bar of a training loop and any other
//! bar a trainer shows while it prepares (indexing scenes, rendering pairs).

pub use indicatif::ProgressBar;
use indicatif::{ProgressDrawTarget, ProgressStyle};

/// Whether a bar is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Visibility {
    /// Drawn on stderr.
    Shown,
    /// Counted but never drawn.
    #[default]
    Hidden,
}

impl Visibility {
    /// [`Visibility::Shown`] when stderr is a terminal (where a bar can be drawn), else hidden.
    pub fn on_terminal() -> Self {
        if std::io::IsTerminal::is_terminal(&std::io::stderr()) { Self::Shown } else { Self::Hidden }
    }
}

/// The step bar at `position` of `total`.
pub fn progress_bar(visibility: Visibility, position: u64, total: u64) -> ProgressBar {
    let bar = styled_bar("{elapsed_precise} [{bar:30}] {pos}/{len} ({eta}) {msg}", visibility, Some(total));
    bar.set_position(position);
    bar
}

/// A bar of the run's style drawn with `template`, of `total` steps when known. A shown bar is drawn only
/// while stderr is a terminal.
pub fn styled_bar(template: &str, visibility: Visibility, total: Option<u64>) -> ProgressBar {
    let target = match visibility {
        Visibility::Shown => ProgressDrawTarget::stderr(),
        Visibility::Hidden => ProgressDrawTarget::hidden(),
    };
    let bar = ProgressBar::with_draw_target(total, target);
    bar.set_style(ProgressStyle::with_template(template).expect("a valid template").progress_chars("=> "));
    bar
}
