//! A small scene with one moving object: a patch of dynamic pixels that slides across three input views of one
//! camera moving along x.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::glam::{DQuat, DVec3};
use dggt_geom::{PinholeIntrinsics, PixelConvention, PosedCamera, WorldFromCamera};
use dggt_model::gaussian_maps::GaussianMaps;
use dggt_scene::{InputView, MeansGradient, PixelGaussians};

pub const W: usize = 24;
pub const H: usize = 16;
pub const S: usize = 3;

pub fn views() -> Vec<InputView> {
    (0..S)
        .map(|i| InputView {
            rig_camera: 0,
            time: i as f64 * 0.5,
            camera: PosedCamera {
                world_from_camera: WorldFromCamera::from_rotation_translation(
                    DQuat::IDENTITY,
                    DVec3::new(i as f64 * 0.3, 0.0, 0.0),
                )
                .unwrap(),
                intrinsics: PinholeIntrinsics::new(20.0, 20.0, W as f64 / 2.0, H as f64 / 2.0).unwrap(),
            },
        })
        .collect()
}

/// Whether pixel `(column, row)` of view `view` shows the moving patch (8 x 6 pixels, two columns further right
/// in each later view).
pub fn in_patch(view: usize, column: usize, row: usize) -> bool {
    (4..10).contains(&row) && (4 + 2 * view..12 + 2 * view).contains(&column)
}

/// Opaque Gaussians with rotations away from the identity (so a turn shows), depth 4 on the patch and 8
/// behind it, dynamic logits +8 on the patch and -8 elsewhere.
pub fn pixels(device: &Device) -> PixelGaussians {
    let mut raw = Vec::with_capacity(S * H * W * 12);
    let mut depth = Vec::with_capacity(S * H * W);
    let mut logit = Vec::with_capacity(S * H * W);
    for view in 0..S {
        for row in 0..H {
            for column in 0..W {
                let patch = in_patch(view, column, row);
                raw.extend([0.3, 0.5, 0.7, 4.0, -2.5, -2.5, -2.5, 1.0, 0.2, -0.3, 0.1, -5.0]);
                depth.push(if patch { 4.0 } else { 8.0 });
                logit.push(if patch { 8.0 } else { -8.0 });
            }
        }
    }
    let maps = GaussianMaps::from_raw(Tensor::from_data(TensorData::new(raw, [1, S, H, W, 12]), device));
    let depth = Tensor::from_data(TensorData::new(depth, [1, S, H, W]), device);
    let logit = Tensor::from_data(TensorData::new(logit, [1, S, H, W]), device);
    PixelGaussians::new(&maps, depth, Some(logit), views(), MeansGradient::Detached, PixelConvention::Centred).unwrap()
}
