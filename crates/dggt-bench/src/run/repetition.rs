//! One timed run of the whole reconstruction of a configuration: the forward pass, the assembly of every
//! target view's Gaussians, the rasterisation, then the backbone alone for its share of the forward time.
//! Each stage is settled before its clock stops.

use std::time::Instant;

use dggt_infer::{CameraSource, InputCameras, input_views};
use dggt_model::Dggt;
use dggt_scene::{AssemblyCounts, TargetView};

use super::outcome::SkipCounts;
use super::prepare::RowSetup;
use super::setup::Runner;
use crate::error::BenchError;
use crate::stages::{self, settle};

/// What one repetition rendered.
pub(super) struct RepetitionOutputs {
    pub(super) counts: Vec<AssemblyCounts>,
    pub(super) sky_gaussians: usize,
    pub(super) skipped: SkipCounts,
    /// Per target view, `[H, W, 3]` (not clamped).
    pub(super) renders: Vec<Vec<f32>>,
}

impl Runner<'_> {
    /// One timed run of the whole reconstruction: `[backbone, heads, assembly, raster]` milliseconds, and what it
    /// rendered.
    pub(super) fn repetition(
        &self,
        model: &Dggt,
        setup: &RowSetup,
    ) -> Result<([f64; 4], RepetitionOutputs), BenchError> {
        let mut clock = Instant::now();
        let lap = |clock: &mut Instant| -> f64 {
            let ms = clock.elapsed().as_secs_f64() * 1e3;
            *clock = Instant::now();
            ms
        };
        let images = &setup.images;
        let aggregator = stages::backbone(model, images.clone())?;
        let prediction = stages::heads(model, aggregator, images.clone(), self.options.chunk_frames, setup.motion)?;
        settle(&prediction.pose_encoding())?;
        settle(&prediction.depth)?;
        if let Some(dynamic) = &prediction.dynamic_logit {
            settle(dynamic)?;
        }
        if let Some(maps) = &prediction.gaussians {
            settle(&maps.opacity)?;
            settle(&maps.rgb)?;
        }
        let forward_ms = lap(&mut clock);

        let cameras = match self.options.poses {
            CameraSource::GroundTruth => InputCameras::Given(setup.input_cameras.clone()),
            CameraSource::Predicted => InputCameras::Predicted,
        };
        let views = input_views(&prediction, &setup.input_slots, cameras, setup.size)?;
        let scene = prediction
            .scene(model, images, views, &setup.timeline, &setup.scene_options)?
            .ok_or_else(|| BenchError::Missing("network: no Gaussian head: nothing to render"))?;
        let mut targets = Vec::new();
        for &(slot, camera) in &setup.target_truth {
            let camera = match self.options.poses {
                CameraSource::GroundTruth => camera,
                CameraSource::Predicted => scene.camera_at(slot.rig_camera, slot.time)?,
            };
            targets.push(TargetView { rig_camera: slot.rig_camera, time: slot.time, camera });
        }
        let assembled = targets.iter().map(|target| scene.assemble(target)).collect::<Result<Vec<_>, _>>()?;
        for gaussians in &assembled {
            settle(&gaussians.gaussians.means)?;
            settle(&gaussians.gaussians.colors)?;
        }
        let assembly_ms = lap(&mut clock);

        let mut renders = Vec::new();
        let mut skipped = SkipCounts { motion_frames: prediction.motion_skipped_frames, sky_views: 0 };
        for (gaussians, target) in assembled.iter().zip(&targets) {
            let rendered = stages::rasterise(&scene, gaussians, target)?;
            skipped.sky_views += usize::from(scene.sky.is_some() && !rendered.sky_rendered);
            renders.push(rendered.rgb);
        }
        let raster_ms = lap(&mut clock);

        // The backbone alone, settled, for its time; the heads' time is the forward pass's less it. (Reading
        // the aggregator's outputs back before the heads run made the heads' outputs NaN on wgpu with burn
        // 0.22.1, so the forward pass above runs without a wait between the two.)
        let aggregator = stages::backbone(model, images.clone())?;
        if let (Some(frame_global), Some(dino)) = (aggregator.output_list.last(), aggregator.dino_token_list.last()) {
            settle(frame_global)?;
            settle(dino)?;
        }
        drop(aggregator);
        let backbone_ms = lap(&mut clock);
        let heads_ms = (forward_ms - backbone_ms).max(0.0);
        let outputs = RepetitionOutputs {
            counts: assembled.iter().map(|a| a.counts).collect(),
            sky_gaussians: scene.sky.as_ref().map_or(0, |s| s.means.dims()[0]),
            skipped,
            renders,
        };
        Ok(([backbone_ms, heads_ms, assembly_ms, raster_ms], outputs))
    }
}
