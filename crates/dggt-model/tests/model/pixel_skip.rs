//! The DPT heads' pixel skip: off in the release's architecture, and when on, each head's output near a pixel
//! follows that pixel (and only pixels within the two 3x3 convolutions' reach), with gradients reaching the
//! skip's convolution.

use burn::tensor::{Device, Distribution, Tensor, TensorData};
use dggt_model::{Dggt, ExtraHeads, ModelConfig};

const H: usize = 28;
const W: usize = 42;

fn values(tensor: Tensor<5>) -> Vec<f32> {
    tensor.into_data().convert::<f32>().try_into_vec::<f32>().unwrap()
}

/// The depth head's raw output for `images` and for `images` with pixel `(row, col)` of frame 0 changed, on the
/// same tokens: `[B, S, H, W, C]` values of each.
fn outputs_with_one_pixel_changed(model: &Dggt, images: &Tensor<5>, [row, col]: [usize; 2]) -> [Vec<f32>; 2] {
    let device = images.device();
    let out = model.forward_with(images.clone(), ExtraHeads::NONE).unwrap();
    let tokens = |i: usize| out.aggregator.output_list[i].clone();
    let (start, grid) = (out.aggregator.patch_start_idx, out.aggregator.grid);
    let changed = images.clone().slice_assign(
        [0..1, 0..1, 0..3, row..row + 1, col..col + 1],
        Tensor::from_data(TensorData::new(vec![0.0f32, 1.0, 0.5], [1, 1, 3, 1, 1]), &device),
    );
    let before = model.depth_head.forward(tokens, start, grid, images).raw;
    let after = model.depth_head.forward(tokens, start, grid, &changed).raw;
    [values(before), values(after)]
}

#[test]
fn the_release_architecture_has_no_pixel_skip() {
    assert!(!ModelConfig::dggt().dpt.pixel_skip && !ModelConfig::tiny().dpt.pixel_skip);
    let device = Device::flex();
    let model = Dggt::new(&ModelConfig::tiny(), &device).unwrap();
    assert!(model.depth_head.pixel_skip.is_none() && model.gs_head.as_ref().unwrap().pixel_skip.is_none());

    let images = Tensor::<5>::random([1, 2, 3, H, W], Distribution::Uniform(0.0, 1.0), &device);
    let [before, after] = outputs_with_one_pixel_changed(&model, &images, [10, 20]);
    assert_eq!(before, after, "without the skip, the head reads only the tokens");
}

#[test]
fn a_pixel_skip_reaches_two_pixels_around_each_pixel_and_learns() {
    let mut config = ModelConfig::tiny();
    config.dpt.pixel_skip = true;
    let device = Device::flex().autodiff();
    device.seed(5);
    let model = Dggt::new(&config, &device).unwrap();
    for head in [Some(&model.depth_head), model.gs_head.as_ref(), model.instance_head.as_ref()] {
        assert!(head.expect("the tiny model has the head").pixel_skip.is_some());
    }

    let images = Tensor::<5>::random([1, 2, 3, H, W], Distribution::Uniform(0.0, 1.0), &device);
    let (row, col) = (10usize, 20usize);
    let [before, after] = outputs_with_one_pixel_changed(&model, &images, [row, col]);
    let channels = before.len() / (2 * H * W);
    for r in 0..H {
        for c in 0..W {
            for frame in 0..2 {
                let at = ((frame * H + r) * W + c) * channels;
                let moved = (0..channels).any(|k| before[at + k] != after[at + k]);
                // A 3x3 convolution of the pixels, then output_conv2's 3x3 convolution: a reach of two pixels.
                let reached = frame == 0 && r.abs_diff(row) <= 2 && c.abs_diff(col) <= 2;
                if !reached {
                    assert!(!moved, "frame {frame} pixel ({r}, {c}) changed with pixel ({row}, {col}) of frame 0");
                }
            }
        }
    }
    let centre = (row * W + col) * channels;
    assert!((0..channels).any(|k| before[centre + k] != after[centre + k]), "the changed pixel's output moved");

    let out = model.forward_with(images, ExtraHeads::NONE).unwrap();
    let grads = out.depth.prediction.sum().backward();
    let skip = model.depth_head.pixel_skip.as_ref().unwrap();
    let gradient = skip.weight.val().grad(&grads).expect("a gradient on the pixel skip");
    assert!(gradient.abs().max().into_scalar::<f32>() > 0.0);
}
