//! A scene evaluated in overlapping forward passes ([`Protocol::passes`]): each pass its own forward pass over
//! its inputs, scoring the frames it alone reports; the records joined into one scene report whose splits are
//! those of the whole window.

use std::path::Path;

use dggt_data::Scene;

use super::scene::evaluate_scene;
use super::setup::{EvalOptions, SceneContext, open_window};
use super::stages::Stopwatch;
use crate::error::EvalError;
use crate::protocol::Protocol;
use crate::report::{SceneReport, summarise_views};

/// Evaluates `scene` (the window of `protocol` at `root`) in `protocol`'s passes.
pub(super) fn evaluate_in_passes(
    root: &Path,
    scene: &Scene,
    protocol: &Protocol,
    context: &SceneContext<'_>,
) -> Result<SceneReport, EvalError> {
    let passes = protocol.passes();
    if passes.len() == 1 {
        return evaluate_scene(root, scene, context);
    }
    let mut joined: Option<SceneReport> = None;
    let mut watch = Stopwatch::default();
    let count = passes.len();
    for (number, pass) in passes.into_iter().enumerate() {
        tracing::info!(
            "pass {} of {count}: inputs {:?}, reporting frames {:?}",
            number + 1,
            pass.protocol.input_frames(),
            pass.scores
        );
        let options = EvalOptions { protocol: pass.protocol.clone(), ..context.options.clone() };
        let pass_context = SceneContext { options: &options, ..*context };
        let pass_scene = open_window(root, &pass.protocol)?;
        let mut report = evaluate_scene(root, &pass_scene, &pass_context)?;
        watch.add_times(&report.stages);
        report.views.retain(|view| pass.scores.contains(&view.frame));
        match &mut joined {
            None => joined = Some(report),
            Some(joined) => {
                joined.views.append(&mut report.views);
                for note in report.notes {
                    if !joined.notes.contains(&note) {
                        joined.notes.push(note);
                    }
                }
            }
        }
    }
    let mut joined = joined.expect("a protocol has at least one pass");
    joined.input_frames = protocol.input_frames();
    joined.splits = protocol.splits().into_iter().map(|split| summarise_views(&joined.views, split)).collect();
    joined.stages = watch.list();
    Ok(joined)
}
