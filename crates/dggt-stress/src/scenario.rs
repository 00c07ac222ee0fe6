//! A small driving-like scenario shared by the stress cases: one rig camera moving forward, input views at
//! log frames `0, 4, 8, ..` and targets between them, each view with its image, sky mask, dynamic mask and a
//! few measured depths, as a training [`StepBatch`] (ground-truth cameras in the first input camera's frame,
//! world-from-camera, OpenCV axes).

use burn::tensor::{Device, Tensor, TensorData};
use dggt_data::random::SplitMix64;
use dggt_geom::{ImageSize, PinholeIntrinsics, PosedCamera, WorldFromCamera};
use dggt_objective::{DepthFlowSamples, StepBatch, ViewTruth};
use dggt_scene::Timeline;
use glam::{DQuat, DVec3};

/// What every view of the scenario shows, on the host.
#[derive(Debug, Clone)]
pub struct ViewContent {
    /// `[H, W, 3]` RGB in `[0, 1]`.
    pub image: Vec<f32>,
    /// `[H, W]` 1 where sky.
    pub sky: Vec<f32>,
    /// `[H, W]` 1 where dynamic.
    pub dynamic: Vec<f32>,
}

/// The scenario: `inputs` input views and `targets` targets between them.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub size: ImageSize,
    pub input_frames: Vec<usize>,
    pub target_frames: Vec<usize>,
    /// Input views then targets.
    pub views: Vec<ViewContent>,
}

/// Log frames between consecutive inputs.
const FRAME_STRIDE: usize = 4;
/// Metres the camera moves per log frame.
const METRES_PER_FRAME: f64 = 0.4;

impl Scenario {
    /// `inputs` inputs (at least one) and up to `targets` targets, with random images, the upper third sky and
    /// a dynamic box.
    pub fn new(size: ImageSize, inputs: usize, targets: usize, seed: u64) -> Self {
        let input_frames: Vec<usize> = (0..inputs.max(1)).map(|i| i * FRAME_STRIDE).collect();
        let last = *input_frames.last().unwrap_or(&0);
        let target_frames: Vec<usize> = if last == 0 {
            vec![0; targets.min(1)]
        } else {
            (0..targets).map(|i| 1 + (i * (last - 1)) / targets.max(1)).collect()
        };
        let mut random = SplitMix64::new(seed);
        let (width, height) = (size.width as usize, size.height as usize);
        let views = (0..input_frames.len() + target_frames.len())
            .map(|_| {
                let image = (0..width * height * 3).map(|_| random.unit()).collect();
                let sky = (0..width * height).map(|p| f32::from(p / width < height / 3)).collect();
                let dynamic = (0..width * height)
                    .map(|p| {
                        let (row, col) = (p / width, p % width);
                        f32::from(row > height / 2 && col > width / 3 && col < width / 2)
                    })
                    .collect();
                ViewContent { image, sky, dynamic }
            })
            .collect();
        Self { size, input_frames, target_frames, views }
    }

    /// Sets every image to `value`.
    pub fn fill_images(&mut self, value: f32) {
        self.views.iter_mut().for_each(|v| v.image.fill(value));
    }

    /// Sets every sky mask to `value`.
    pub fn fill_sky(&mut self, value: f32) {
        self.views.iter_mut().for_each(|v| v.sky.fill(value));
    }

    /// Sets every dynamic mask to `value`.
    pub fn fill_dynamic(&mut self, value: f32) {
        self.views.iter_mut().for_each(|v| v.dynamic.fill(value));
    }

    /// The ground-truth camera at log frame `frame`: moving along +z, yawing slightly.
    pub fn camera(&self, frame: usize) -> PosedCamera {
        let f = frame as f64;
        let world_from_camera = WorldFromCamera::from_rotation_translation(
            DQuat::from_rotation_y(0.01 * f),
            DVec3::new(0.0, 0.0, METRES_PER_FRAME * f),
        )
        .expect("a finite pose");
        let (w, h) = (self.size.width as f64, self.size.height as f64);
        let intrinsics = PinholeIntrinsics::new(0.8 * w, 0.8 * w, w / 2.0, h / 2.0).expect("valid intrinsics");
        PosedCamera { world_from_camera, intrinsics }
    }

    /// The network's input `[1, S, 3, H, W]` (planar) of the input views.
    pub fn input_images(&self, device: &Device) -> Tensor<5> {
        let (width, height) = (self.size.width as usize, self.size.height as usize);
        let plane = width * height;
        let data: Vec<f32> = self.views[..self.input_frames.len()]
            .iter()
            .flat_map(|v| (0..3).flat_map(move |c| (0..plane).map(move |p| v.image[3 * p + c])))
            .collect();
        Tensor::from_data(TensorData::new(data, [1, self.input_frames.len(), 3, height, width]), device)
    }

    /// The scenario as a training batch: depths measured at every 7th pixel below the sky (10 m, but 1e-4 m
    /// and 1e4 m at the first two of them, so the log-depth loss sees both ends), and scene flow there (every
    /// third of those cells moving at `(1, 0, 0.5)` m per log frame, so the flow losses see moving and still
    /// cells).
    pub fn batch(&self, device: &Device) -> StepBatch {
        let timeline = Timeline::new(&self.input_frames).expect("input frames");
        let (width, height) = (self.size.width as usize, self.size.height as usize);
        let truth = |frame: usize, view: &ViewContent, with_depth: bool| {
            let pixels: Vec<i64> =
                (0..width * height).filter(|&p| p % 7 == 0 && view.sky[p] < 0.5).map(|p| p as i64).collect();
            let depths: Vec<f32> = (0..pixels.len()).map(|i| [1e-4, 1e4].get(i).copied().unwrap_or(10.0)).collect();
            let moving: Vec<bool> = (0..pixels.len()).map(|i| i % 3 == 0).collect();
            let velocities = moving.iter().map(|&m| if m { [1.0, 0.0, 0.5] } else { [0.0; 3] }).collect();
            ViewTruth {
                frame,
                rig_camera: 0,
                time: timeline.time(frame as f64),
                camera: self.camera(frame),
                image: Tensor::from_data(TensorData::new(view.image.clone(), [height, width, 3]), device),
                sky: Some(Tensor::from_data(TensorData::new(view.sky.clone(), [height, width]), device)),
                dynamic: Some(Tensor::from_data(TensorData::new(view.dynamic.clone(), [height, width]), device)),
                depth_flow: (with_depth && !pixels.is_empty()).then_some(DepthFlowSamples {
                    pixels,
                    depths,
                    velocities: Some(velocities),
                    moving,
                }),
            }
        };
        let inputs = self.input_frames.iter().zip(&self.views).map(|(&f, v)| truth(f, v, true)).collect();
        let targets = self
            .target_frames
            .iter()
            .zip(&self.views[self.input_frames.len()..])
            .map(|(&f, v)| truth(f, v, false))
            .collect();
        StepBatch { step: 0, images: self.input_images(device), size: self.size, timeline, inputs, targets }
    }
}
