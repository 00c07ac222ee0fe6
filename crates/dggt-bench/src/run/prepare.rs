//! The fixed inputs of one configuration, built before its repetitions so that they are not timed: the input
//! images at the row's width, the input and target slots, the export's cameras relative to the first input
//! view, the refiner's reference views, and how the scene is assembled.

use burn::tensor::{Tensor, TensorData};
use dggt_data::PreparedView;
use dggt_geom::{ImageSize, PosedCamera};
use dggt_infer::{MotionPath, SceneOptions, ViewSlot};
use dggt_refine::ReferenceView;
use dggt_scene::{AssemblySettings, Timeline, nearest_in_time};

use super::setup::{Runner, TargetImages};
use crate::error::BenchError;
use crate::knobs::{Culling, Knobs};

/// The fixed inputs of one configuration's repetitions.
pub(super) struct RowSetup {
    /// `[1, S, 3, H, W]` f32.
    pub(super) images: Tensor<5>,
    pub(super) size: ImageSize,
    pub(super) timeline: Timeline,
    pub(super) input_slots: Vec<ViewSlot>,
    /// The export's cameras of the inputs, relative to the first input view.
    pub(super) input_cameras: Vec<PosedCamera>,
    /// The targets' slots and export cameras.
    pub(super) target_truth: Vec<(ViewSlot, PosedCamera)>,
    pub(super) scene_options: SceneOptions,
    pub(super) motion: MotionPath,
    /// Per target, the refiner's reference view `[H, W, 3]`: the input view of its camera nearest in time,
    /// when the refiner takes one; empty otherwise.
    pub(super) references: Vec<Vec<f32>>,
}

impl Runner<'_> {
    /// The inputs of one configuration: images, input and target slots, the export's cameras (relative to the
    /// first input view), and how the scene is built.
    pub(super) fn prepare(
        &mut self,
        knobs: &Knobs,
        inputs: &[usize],
        targets: &[TargetImages],
    ) -> Result<RowSetup, BenchError> {
        let cameras = self.scene.cameras.len();
        let mut input_views = Vec::new();
        for &frame in inputs {
            for camera in 0..cameras {
                input_views.push(self.cache.get(knobs.width, frame, camera)?.clone());
            }
        }
        let mut target_views = Vec::new();
        for target in targets {
            target_views.push(self.cache.get(knobs.width, target.frame, target.camera)?.clone());
        }
        let size = input_views[0].image.size;
        let (h, w) = (size.height as usize, size.width as usize);
        let planar: Vec<f32> = input_views.iter().flat_map(|v| v.image.data.iter().copied()).collect();
        // f32 images: the network casts its input to its own float type.
        let images = Tensor::<5>::from_data(TensorData::new(planar, [1, input_views.len(), 3, h, w]), self.device);

        let frame_index = |position: usize| self.scene.frames[position].index;
        let timeline = Timeline::new(&inputs.iter().map(|&f| frame_index(f)).collect::<Vec<_>>())?;
        let reference_pose = input_views[0].world_from_camera;
        let truth = |view: &PreparedView| {
            let slot = ViewSlot { rig_camera: view.camera, time: timeline.time(frame_index(view.frame) as f64) };
            let camera = PosedCamera {
                world_from_camera: view.world_from_camera.relative_to(&reference_pose),
                intrinsics: view.intrinsics,
            };
            (slot, camera)
        };
        let (input_slots, input_cameras): (Vec<ViewSlot>, _) = input_views.iter().map(truth).unzip();
        let target_truth: Vec<(ViewSlot, PosedCamera)> = target_views.iter().map(truth).collect();
        let references = match self.options.refine.as_ref().map(|spec| spec.reference) {
            Some(ReferenceView::NearestInput) => target_truth
                .iter()
                .map(|(slot, _)| {
                    let candidates = input_slots.iter().map(|s| (s.rig_camera, s.time));
                    let position = nearest_in_time(candidates, slot.rig_camera, slot.time)
                        .ok_or_else(|| BenchError::NoReferenceView { camera: slot.rig_camera })?;
                    Ok(input_views[position].image.interleaved())
                })
                .collect::<Result<Vec<_>, BenchError>>()?,
            Some(ReferenceView::None) | None => Vec::new(),
        };
        let assembly = match knobs.culling {
            Culling::Off => AssemblySettings::exact(),
            Culling::MinOpacity(min_opacity) => AssemblySettings { min_opacity, ..AssemblySettings::default() },
        };
        let assembly =
            AssemblySettings { hidden_sky: knobs.skips.hidden_sky(), dynamic_motion: knobs.motion, ..assembly };
        let scene_options = SceneOptions { sky: knobs.sky, assembly, ..SceneOptions::default() };
        let motion = knobs.skips.motion();
        Ok(RowSetup {
            images,
            size,
            timeline,
            input_slots,
            input_cameras,
            target_truth,
            scene_options,
            motion,
            references,
        })
    }
}
