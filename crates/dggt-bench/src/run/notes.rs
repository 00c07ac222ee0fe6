//! The notes every report carries whatever its rows: what refinement, culling and precision mean here, what
//! each error is measured against and at which size, and how the times are taken.

use dggt_geom::ImageSize;
use dggt_infer::{CameraSource, SkyChoice};

use super::options::BenchOptions;

pub(super) fn standing_notes(options: &BenchOptions, reference_size: ImageSize) -> Vec<String> {
    let base = options.sweep.baseline;
    let refinement = match &options.refine {
        None => "refinement: no diffusion refiner given (--refine MODEL_DIR): renders are scored unrefined".into(),
        Some(spec) => format!(
            "refinement: every row's target renders also refined by {} one frame at a time at the row's render \
             size (refine_ms: median of the repetitions, not in total_ms), scored against the truth at the \
             reference size",
            spec.describe()
        ),
    };
    vec![
        refinement,
        format!(
            "culling: the assembly has one opacity threshold (AssemblySettings::min_opacity), compared with each \
             Gaussian's opacity after the lifespan fade at the target time, so it is also the lifespan cutoff; there \
             is no separate lifespan knob. Every row but the exact one also drops Gaussians whose footprint misses \
             the image. The rasteriser itself skips alpha below 1/255 (dggt_scene::MIN_OPACITY), so a 1/255 \
             threshold only removes work"
        ),
        format!(
            "precision: applies to the network (aggregator and heads; parameters and input cast, outputs cast back \
             to f32); the sky model, assembly and rasteriser always compute in f32"
        ),
        format!(
            "vs exact: each row's target renders against the exact render (width {} px, {} input frames, culling \
             off, f32, sky {}), all at {}; renders of other sizes are resized to it full frame to full frame with \
             a triangle filter (bilinear, antialiased when shrinking); PSNR is infinite where they are identical",
            base.width,
            base.input_frames,
            if base.sky == SkyChoice::Render { "on" } else { "off" },
            reference_size
        ),
        format!(
            "vs truth: against the export's images of the target frames, preprocessed to {reference_size}; cameras \
             from {}",
            match options.poses {
                CameraSource::GroundTruth => "the export's poses (relative to the first input view)",
                CameraSource::Predicted => "the camera head (targets interpolated between input views)",
            }
        ),
        format!(
            "times: median of {} repetitions after {} warm-up runs; image decoding and preprocessing are not \
             timed",
            options.repeat, options.warmup
        ),
    ]
}
