//! The refiner's training shown live (`dggt refine-train --rerun FILE.rrd` or `--rerun-connect URL`) on the
//! `step` time line, through a [`LiveRecording`].
//!
//! Entities: `refine/loss`, `refine/l2`, `refine/lpips`, `refine/gram`, `refine/grad_norm` (each step, as
//! `metrics.jsonl` has them); `validation/scores/refined_psnr` and `render_psnr` at each validation pass; and
//! for the first `[viewer] refiner_pairs` held-out pairs, `validation/pair_N/{render, refined, target}`: the
//! render before refining, after, and the truth.

use dggt_refine_train::pairs::Image;
use dggt_refine_train::records::{StepRecord, Validation};
use dggt_refine_train::{RefineWatcher, RefinedPicture};
use dggt_run::ViewerSection;

use crate::components::{part_tabs, rgb_image};
use crate::error::RerunError;
use crate::live::{Destination, LiveRecording, LiveReport, scalars, send};

/// The images of a pictured pair, in the layout's order.
const PARTS: [&str; 3] = ["render", "refined", "target"];

/// A refiner run's live recording: a [`RefineWatcher`] that queues what it is shown.
pub struct RefinerRecording {
    live: LiveRecording,
    settings: ViewerSection,
    validations_seen: u64,
}

impl RefinerRecording {
    /// Opens the recording at `destination` with a layout for `pairs` pictured held-out pairs.
    pub fn start(destination: Destination, settings: ViewerSection, pairs: usize) -> Result<Self, RerunError> {
        let live =
            LiveRecording::start(destination, "dggt_refiner_training", layout(pairs.min(settings.refiner_pairs)))?;
        Ok(Self { live, settings, validations_seen: 0 })
    }

    /// Waits for what is queued; returns what was recorded.
    pub fn finish(self) -> LiveReport {
        self.live.finish()
    }
}

impl RefineWatcher for RefinerRecording {
    fn step(&mut self, record: &StepRecord) {
        if !record.step.is_multiple_of(self.settings.scalars_every) {
            return;
        }
        let mut values: Vec<(String, f64)> =
            [("loss", record.loss), ("l2", record.l2), ("lpips", record.lpips), ("gram", record.gram)]
                .into_iter()
                .map(|(name, value)| (name.to_owned(), value))
                .collect();
        values.extend(record.grad_norm.map(|norm| ("grad_norm".to_owned(), norm)));
        self.live.step(record.step, scalars("refine", values));
    }

    fn pictures_wanted(&self) -> usize {
        if self.settings.pictures_pass(self.validations_seen) { self.settings.refiner_pairs } else { 0 }
    }

    fn validation(&mut self, validation: &Validation, pictures: &[RefinedPicture]) {
        self.validations_seen += 1;
        let scores = vec![
            ("refined_psnr".to_owned(), validation.refined_psnr),
            ("render_psnr".to_owned(), validation.render_psnr),
        ];
        let log_scores = scalars("validation/scores", scores);
        let pictures = pictures.to_vec();
        self.live.validation(
            validation.step,
            Box::new(move |recording| {
                log_scores(recording)?;
                for picture in &pictures {
                    let images = [&picture.render, &picture.refined, &picture.target];
                    for (part, image) in PARTS.iter().zip(images) {
                        send(recording, &format!("validation/pair_{}/{part}", picture.index), &image_of(image))?;
                    }
                }
                Ok(())
            }),
        );
    }
}

fn image_of(image: &Image) -> rerun::Image {
    let size = dggt_geom::ImageSize { width: image.width as u32, height: image.height as u32 };
    rgb_image(size, &image.values)
}

/// The layout: the losses and the validation scores over the steps, and per pictured pair tabs of its render,
/// refined render and target.
fn layout(pairs: usize) -> rerun::blueprint::Blueprint {
    use rerun::blueprint::{Blueprint, ContainerLike, Grid, Horizontal, TimeSeriesView, Vertical};
    let losses: ContainerLike = TimeSeriesView::new("losses").with_origin("refine").into();
    let scores: ContainerLike = TimeSeriesView::new("validation scores").with_origin("validation/scores").into();
    let pair_tabs =
        |index: usize| part_tabs(&format!("held-out pair {index}"), &format!("validation/pair_{index}"), &PARTS);
    let curves: ContainerLike = Vertical::new([losses, scores]).into();
    let pictures: ContainerLike = Grid::new((0..pairs).map(pair_tabs)).into();
    Blueprint::new(Horizontal::new([curves, pictures]))
}
