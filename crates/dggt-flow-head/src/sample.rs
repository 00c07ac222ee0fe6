//! Image features at given pixels, read from maps of several scales of one image.
//!
//! Convention: pixels are named at the full image resolution `H x W` (row `y`, column `x`, 0-based), and a pixel
//! stands for its centre. A map of size `H_s x W_s` covers the same image, its pixel centres aligned with the
//! image's (`align_corners = false`): pixel `(row, col)` maps to
//!
//! `x_s = (col + 0.5) * W_s / W - 0.5`, `y_s = (row + 0.5) * H_s / H - 0.5`,
//!
//! clamped to `[0, W_s - 1]` and `[0, H_s - 1]` (the border value extends outwards), and the map is read there
//! bilinearly. At full resolution this is the map's value at the pixel itself. The corner indices and weights are
//! computed on the host; the values are gathered and weighted with tensor operations, so gradients reach the maps.
//! The scales' samples are concatenated along channels in the order of the maps.

use burn::tensor::{Int, Tensor, TensorData};
use dggt_geom::ImageSize;

/// A pixel of the full-resolution image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelIndex {
    pub row: usize,
    pub col: usize,
}

/// Why features could not be sampled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SampleError {
    #[error("no feature maps given")]
    NoMaps,
    #[error("feature map {scale} is empty ({height} x {width})")]
    EmptyMap { scale: usize, height: usize, width: usize },
    #[error("frame {frame} asked of feature map {scale}, which has {frames} frames")]
    FrameOutOfRange { scale: usize, frame: usize, frames: usize },
    #[error("pixel {index} at row {row}, column {col} lies outside the {height} x {width} image")]
    PixelOutside { index: usize, row: usize, col: usize, height: usize, width: usize },
}

/// The features of `frame` at `pixels`: `[N, sum C_s]`, scale after scale, from `maps`, each `[frames, C_s, H_s,
/// W_s]` (see the module's doc for the sampling convention).
pub fn sample_features(
    maps: &[Tensor<4>],
    frame: usize,
    image: ImageSize,
    pixels: &[PixelIndex],
) -> Result<Tensor<2>, SampleError> {
    check(maps, frame, image, pixels)?;
    if pixels.is_empty() {
        // burn's `reshape` reads a 0 as "keep this dimension", so no pixels is answered here.
        let channels = maps.iter().map(|m| m.dims()[1]).sum::<usize>();
        return Ok(Tensor::zeros([0, channels], (&maps[0].device(), maps[0].dtype())));
    }
    let samples = maps.iter().map(|map| sample_scale(map.clone(), frame, image, pixels)).collect();
    Ok(Tensor::cat(samples, 1))
}

fn check(maps: &[Tensor<4>], frame: usize, image: ImageSize, pixels: &[PixelIndex]) -> Result<(), SampleError> {
    if maps.is_empty() {
        return Err(SampleError::NoMaps);
    }
    for (scale, map) in maps.iter().enumerate() {
        let [frames, _, height, width] = map.dims();
        if height == 0 || width == 0 {
            return Err(SampleError::EmptyMap { scale, height, width });
        }
        if frame >= frames {
            return Err(SampleError::FrameOutOfRange { scale, frame, frames });
        }
    }
    let (height, width) = (image.height as usize, image.width as usize);
    match pixels.iter().position(|p| p.row >= height || p.col >= width) {
        Some(index) => {
            let PixelIndex { row, col } = pixels[index];
            Err(SampleError::PixelOutside { index, row, col, height, width })
        }
        None => Ok(()),
    }
}

/// One map's bilinear samples, `[N, C_s]`.
fn sample_scale(map: Tensor<4>, frame: usize, image: ImageSize, pixels: &[PixelIndex]) -> Tensor<2> {
    let [_, channels, height, width] = map.dims();
    let device = map.device();
    let dtype = map.dtype();
    // [H_s * W_s, C_s]: one row per map pixel.
    let plane = map.narrow(0, frame, 1).reshape([channels, height * width]).swap_dims(0, 1);
    let taps = CornerTaps::new(pixels, image, [height, width]);
    let n = pixels.len();
    let rows = Tensor::<1, Int>::from_data(TensorData::new(taps.rows, [4 * n]), &device);
    let weights = Tensor::<1>::from_data(TensorData::new(taps.weights, [4 * n]), (&device, dtype));
    let corners = plane.select(0, rows).reshape([4, n, channels]);
    (corners * weights.reshape([4, n, 1])).sum_dim(0).reshape([n, channels])
}

/// The four corners of every pixel's bilinear sample: map rows and weights, corner-major (`[4, N]` flattened:
/// top-left, top-right, bottom-left, bottom-right).
struct CornerTaps {
    rows: Vec<i64>,
    weights: Vec<f32>,
}

impl CornerTaps {
    fn new(pixels: &[PixelIndex], image: ImageSize, [height, width]: [usize; 2]) -> Self {
        let n = pixels.len();
        let (mut rows, mut weights) = (vec![0i64; 4 * n], vec![0f32; 4 * n]);
        for (i, pixel) in pixels.iter().enumerate() {
            let y = AxisTaps::new(pixel.row, image.height as usize, height);
            let x = AxisTaps::new(pixel.col, image.width as usize, width);
            let corners = [(y.low, x.low), (y.low, x.high), (y.high, x.low), (y.high, x.high)];
            for (corner, ((yi, wy), (xi, wx))) in corners.into_iter().enumerate() {
                rows[corner * n + i] = (yi * width + xi) as i64;
                weights[corner * n + i] = (wy * wx) as f32;
            }
        }
        Self { rows, weights }
    }
}

/// The two map indices around one image coordinate and their weights.
struct AxisTaps {
    low: (usize, f64),
    high: (usize, f64),
}

impl AxisTaps {
    /// Image index `index` of `full` pixels, in a map of `scaled` pixels along the same axis.
    fn new(index: usize, full: usize, scaled: usize) -> Self {
        let last = (scaled - 1) as f64;
        let position = ((index as f64 + 0.5) * scaled as f64 / full as f64 - 0.5).clamp(0.0, last);
        let low = position.floor();
        let fraction = position - low;
        let high = (low + 1.0).min(last);
        Self { low: (low as usize, 1.0 - fraction), high: (high as usize, fraction) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Device;

    fn map(values: Vec<f32>, shape: [usize; 4], device: &Device) -> Tensor<4> {
        Tensor::from_data(TensorData::new(values, shape), device)
    }

    fn host(t: Tensor<2>) -> Vec<f32> {
        t.try_into_vec_as::<f32>().unwrap()
    }

    fn ramp(n: usize) -> Vec<f32> {
        (0..n).map(|i| (i as f32 * 0.37).sin() * 10.0).collect()
    }

    fn pixel(row: usize, col: usize) -> PixelIndex {
        PixelIndex { row, col }
    }

    #[test]
    fn full_resolution_returns_the_pixel_value_exactly() {
        let device = Device::flex();
        let (frames, channels, h, w) = (2, 3, 5, 7);
        let values = ramp(frames * channels * h * w);
        let maps = [map(values.clone(), [frames, channels, h, w], &device)];
        let pixels = [pixel(0, 0), pixel(4, 6), pixel(2, 3), pixel(1, 5)];
        let got = host(sample_features(&maps, 1, ImageSize { height: h as u32, width: w as u32 }, &pixels).unwrap());
        for (i, p) in pixels.iter().enumerate() {
            for c in 0..channels {
                let expected = values[((channels + c) * h + p.row) * w + p.col];
                assert_eq!(got[i * channels + c], expected, "pixel {p:?} channel {c}");
            }
        }
    }

    #[test]
    fn half_resolution_is_bilinear_between_pixel_centres() {
        let device = Device::flex();
        // A 2 x 3 map of an image of 4 x 6 pixels, one channel.
        let half = map(vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0], [1, 1, 2, 3], &device);
        let full = map(ramp(4 * 6), [1, 1, 4, 6], &device);
        let image = ImageSize { height: 4, width: 6 };
        // Pixel (1, 2): y = 1.5 / 2 - 0.5 = 0.25, x = 2.5 / 2 - 0.5 = 0.75:
        // 0.75 * (0.25 * 0 + 0.75 * 1) + 0.25 * (0.25 * 10 + 0.75 * 11) = 3.25.
        // Pixel (0, 0): y = x = -0.25, clamped to the corner value 0.
        // Pixel (3, 5): y = 1.25 -> 1, x = 2.25 -> 2: the corner value 12.
        let pixels = [pixel(1, 2), pixel(0, 0), pixel(3, 5)];
        let got = host(sample_features(&[full, half], 0, image, &pixels).unwrap());
        let expected_half = [3.25, 0.0, 12.0];
        let ramp = ramp(24);
        for (i, p) in pixels.iter().enumerate() {
            assert_eq!(got[2 * i], ramp[p.row * 6 + p.col]);
            assert!((got[2 * i + 1] - expected_half[i]).abs() < 1e-6, "{p:?}: {}", got[2 * i + 1]);
        }
    }

    #[test]
    fn gradients_reach_the_maps_with_the_bilinear_weights() {
        let device = Device::flex().autodiff();
        let half = map(vec![0.0; 6], [1, 1, 2, 3], &device).require_grad();
        let image = ImageSize { height: 4, width: 6 };
        let sample = sample_features(std::slice::from_ref(&half), 0, image, &[pixel(1, 2)]).unwrap();
        let grad = half.grad(&sample.sum().backward()).unwrap();
        let grad = grad.try_into_vec_as::<f32>().unwrap();
        let expected = [0.1875, 0.5625, 0.0, 0.0625, 0.1875, 0.0];
        for (g, e) in grad.iter().zip(expected) {
            assert!((g - e).abs() < 1e-6, "{grad:?}");
        }
    }

    #[test]
    fn bad_requests_are_named() {
        let device = Device::flex();
        let maps = [map(vec![0.0; 6], [1, 1, 2, 3], &device)];
        let image = ImageSize { height: 4, width: 6 };
        assert_eq!(sample_features(&[], 0, image, &[]).unwrap_err(), SampleError::NoMaps);
        assert_eq!(
            sample_features(&maps, 1, image, &[]).unwrap_err(),
            SampleError::FrameOutOfRange { scale: 0, frame: 1, frames: 1 }
        );
        assert_eq!(
            sample_features(&maps, 0, image, &[pixel(0, 0), pixel(4, 0)]).unwrap_err(),
            SampleError::PixelOutside { index: 1, row: 4, col: 0, height: 4, width: 6 }
        );
        let empty = [map(vec![], [1, 1, 0, 3], &device)];
        assert!(matches!(sample_features(&empty, 0, image, &[]), Err(SampleError::EmptyMap { scale: 0, .. })));
        assert_eq!(sample_features(&maps, 0, image, &[]).unwrap().dims(), [0, 1]);
    }
}
