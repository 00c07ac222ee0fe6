//! Image quality: PSNR and SSIM
//! as scikit-image computes them with the arguments the project's evaluation uses (data range 1).
//!
//! Buffers are channel-last `[H, W, C]` f32 slices (row-major, the layout of one view of the rasteriser's
//! `[V, H, W, 3]` output) with linear values; both metrics clamp the values to [0, 1] first, as the
//! evaluation clamps the rendered and target images. [`image_metrics`] takes `[V, H, W, C]` tensors.
//!
//! * PSNR: `10 log10(1 / MSE)`, the squared differences in f32 (as from f32 images) summed in f64; infinite
//!   for identical images.
//! * SSIM (skimage defaults, Gaussian weights off): per channel, 7x7 uniform means (borders reflected,
//!   `d c b a | a b c d | d c b a`) of `x`, `y`, `x^2`, `y^2`, `x y`; sample (co)variances (factor 49/48);
//!   `C1 = 0.01^2`, `C2 = 0.03^2`; `S = (2 ux uy + C1)(2 vxy + C2) / ((ux^2 + uy^2 + C1)(vx + vy + C2))`;
//!   the channel's value is the mean of `S` without a 3-pixel border (exactly the pixels whose window lies
//!   inside the image, so the border rule does not change it); SSIM is the mean over the channels.
//!   Computed in f64 throughout (skimage keeps f32 maps for f32 inputs; the difference is ~1e-7).

use burn::tensor::Tensor;

use crate::error::MetricError;

/// Side of the SSIM window.
pub const SSIM_WINDOW: usize = 7;
/// `(K1 L)^2` with `K1 = 0.01`, data range `L = 1`.
pub const SSIM_C1: f64 = 0.01 * 0.01;
/// `(K2 L)^2` with `K2 = 0.03`, data range `L = 1`.
pub const SSIM_C2: f64 = 0.03 * 0.03;

/// Height, width and channels of a channel-last image buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageShape {
    pub height: usize,
    pub width: usize,
    pub channels: usize,
}

impl ImageShape {
    pub fn new(height: usize, width: usize, channels: usize) -> Self {
        Self { height, width, channels }
    }

    /// Number of values `H W C`.
    pub fn len(&self) -> usize {
        self.height * self.width * self.channels
    }

    /// Whether the image has no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// SSIM of one image pair.
#[derive(Debug, Clone, PartialEq)]
pub struct Ssim {
    /// Mean over the channels.
    pub value: f64,
    /// Per channel, in buffer order (R, G, B).
    pub per_channel: Vec<f64>,
}

/// PSNR and SSIM of one image pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageMetrics {
    pub psnr: f64,
    pub ssim: f64,
}

fn check_buffers(metric: &'static str, a: &[f32], b: &[f32], shape: ImageShape) -> Result<(), MetricError> {
    if shape.is_empty() || a.len() != shape.len() || b.len() != shape.len() {
        let ImageShape { height, width, channels } = shape;
        return Err(MetricError::ImageBuffers { metric, rendered: a.len(), truth: b.len(), height, width, channels });
    }
    Ok(())
}

/// PSNR in dB of two equally long buffers with values clamped to [0, 1] (data range 1).
pub fn psnr(a: &[f32], b: &[f32]) -> Result<f64, MetricError> {
    crate::error::check_lengths("PSNR", a.len(), b.len())?;
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| {
            let d = x.clamp(0.0, 1.0) - y.clamp(0.0, 1.0);
            f64::from(d * d)
        })
        .sum();
    let mse = sum / a.len() as f64;
    Ok(10.0 * (1.0 / mse).log10())
}

/// PSNR in dB over the pixels of interleaved `[.., channels]` images where `mask` (one entry per pixel) is set:
/// the region of moving objects, say. [`MetricError::Empty`] when no pixel is set.
pub fn masked_psnr(a: &[f32], b: &[f32], channels: usize, mask: &[bool]) -> Result<f64, MetricError> {
    const METRIC: &str = "masked PSNR";
    crate::error::check_lengths(METRIC, a.len(), b.len())?;
    crate::error::check_lengths(METRIC, a.len(), mask.len() * channels)?;
    let pick = |image: &[f32]| -> Vec<f32> {
        image
            .chunks_exact(channels)
            .zip(mask)
            .filter(|(_, set)| **set)
            .flat_map(|(pixel, _)| pixel.iter().copied())
            .collect()
    };
    let (a, b) = (pick(a), pick(b));
    if a.is_empty() {
        return Err(MetricError::Empty { metric: METRIC });
    }
    psnr(&a, &b)
}

/// Reflected index (`d c b a | a b c d | d c b a`) for `-n <= i < 2n`.
fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    (if i < 0 {
        -i - 1
    } else if i >= n {
        2 * n - i - 1
    } else {
        i
    }) as usize
}

/// 7x7 uniform mean of an `[H, W]` plane with reflected borders.
fn uniform_filter(plane: &[f64], height: usize, width: usize) -> Vec<f64> {
    let r = (SSIM_WINDOW / 2) as isize;
    let scale = 1.0 / SSIM_WINDOW as f64;
    let mut rows = vec![0.0; plane.len()];
    for y in 0..height {
        let row = &plane[y * width..(y + 1) * width];
        for x in 0..width {
            rows[y * width + x] = (-r..=r).map(|k| row[reflect(x as isize + k, width)]).sum::<f64>() * scale;
        }
    }
    let mut out = vec![0.0; plane.len()];
    for y in 0..height {
        for x in 0..width {
            out[y * width + x] =
                (-r..=r).map(|k| rows[reflect(y as isize + k, height) * width + x]).sum::<f64>() * scale;
        }
    }
    out
}

/// The SSIM map `S` of one channel, `[H, W]`, borders included.
fn channel_map(a: &[f32], b: &[f32], shape: ImageShape, channel: usize) -> Vec<f64> {
    let plane = |buffer: &[f32]| -> Vec<f64> {
        buffer.iter().skip(channel).step_by(shape.channels).map(|&v| f64::from(v.clamp(0.0, 1.0))).collect()
    };
    let (x, y) = (plane(a), plane(b));
    let (h, w) = (shape.height, shape.width);
    let product = |p: &[f64], q: &[f64]| -> Vec<f64> { p.iter().zip(q).map(|(u, v)| u * v).collect() };
    let ux = uniform_filter(&x, h, w);
    let uy = uniform_filter(&y, h, w);
    let uxx = uniform_filter(&product(&x, &x), h, w);
    let uyy = uniform_filter(&product(&y, &y), h, w);
    let uxy = uniform_filter(&product(&x, &y), h, w);
    let n = (SSIM_WINDOW * SSIM_WINDOW) as f64;
    let cov_norm = n / (n - 1.0);
    (0..h * w)
        .map(|i| {
            let vx = cov_norm * (uxx[i] - ux[i] * ux[i]);
            let vy = cov_norm * (uyy[i] - uy[i] * uy[i]);
            let vxy = cov_norm * (uxy[i] - ux[i] * uy[i]);
            let numerator = (2.0 * ux[i] * uy[i] + SSIM_C1) * (2.0 * vxy + SSIM_C2);
            let denominator = (ux[i] * ux[i] + uy[i] * uy[i] + SSIM_C1) * (vx + vy + SSIM_C2);
            numerator / denominator
        })
        .collect()
}

fn check_ssim_size(shape: ImageShape) -> Result<(), MetricError> {
    if shape.height < SSIM_WINDOW || shape.width < SSIM_WINDOW {
        return Err(MetricError::TooSmall { window: SSIM_WINDOW, height: shape.height, width: shape.width });
    }
    Ok(())
}

/// The full SSIM map `[H, W, C]` (skimage's `full=True` map, reflected borders).
pub fn ssim_map(a: &[f32], b: &[f32], shape: ImageShape) -> Result<Vec<f64>, MetricError> {
    check_buffers("SSIM", a, b, shape)?;
    check_ssim_size(shape)?;
    let maps: Vec<Vec<f64>> = (0..shape.channels).map(|c| channel_map(a, b, shape, c)).collect();
    Ok((0..shape.height * shape.width).flat_map(|i| maps.iter().map(move |m| m[i])).collect())
}

/// SSIM of two `[H, W, C]` buffers (H, W >= 7): per channel and the mean over channels.
pub fn ssim(a: &[f32], b: &[f32], shape: ImageShape) -> Result<Ssim, MetricError> {
    check_buffers("SSIM", a, b, shape)?;
    check_ssim_size(shape)?;
    let pad = SSIM_WINDOW / 2;
    let (h, w) = (shape.height, shape.width);
    let per_channel: Vec<f64> = (0..shape.channels)
        .map(|c| {
            let map = channel_map(a, b, shape, c);
            let inner: f64 =
                (pad..h - pad).flat_map(|y| (pad..w - pad).map(move |x| (y, x))).map(|(y, x)| map[y * w + x]).sum();
            inner / ((h - 2 * pad) * (w - 2 * pad)) as f64
        })
        .collect();
    let value = per_channel.iter().sum::<f64>() / per_channel.len() as f64;
    Ok(Ssim { value, per_channel })
}

/// PSNR and SSIM per view of two `[V, H, W, C]` tensors (read to the host).
pub fn image_metrics(rendered: Tensor<4>, target: Tensor<4>) -> Result<Vec<ImageMetrics>, MetricError> {
    let dims = rendered.dims();
    if dims != target.dims() {
        return Err(MetricError::BatchShapes { rendered: dims, truth: target.dims() });
    }
    let [views, height, width, channels] = dims;
    let shape = ImageShape::new(height, width, channels);
    let host = |t: Tensor<4>, which: &'static str| -> Result<Vec<f32>, MetricError> {
        t.detach()
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .map_err(|e| MetricError::Unreadable { which, detail: format!("{e:?}") })
    };
    let (a, b) = (host(rendered, "rendered")?, host(target, "true")?);
    let n = shape.len();
    (0..views)
        .map(|v| {
            let (a, b) = (&a[v * n..(v + 1) * n], &b[v * n..(v + 1) * n]);
            Ok(ImageMetrics { psnr: psnr(a, b)?, ssim: ssim(a, b, shape)?.value })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_repeats_the_edge() {
        let n = 5;
        let got: Vec<usize> = (-3..8).map(|i| reflect(i, n)).collect();
        assert_eq!(got, [2, 1, 0, 0, 1, 2, 3, 4, 4, 3, 2]);
    }

    #[test]
    fn masked_psnr_looks_only_at_the_masked_pixels() {
        // Two RGB pixels: the first off by 0.1 in every channel, the second off by 0.5.
        let (a, b) = ([0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.1, 0.1, 0.1, 0.5, 0.5, 0.5]);
        let first = masked_psnr(&a, &b, 3, &[true, false]).unwrap();
        assert!((first - 20.0).abs() < 1e-5, "{first}");
        let second = masked_psnr(&a, &b, 3, &[false, true]).unwrap();
        assert!((second - 10.0 * 4f64.log10()).abs() < 1e-5, "{second}");
        assert!(matches!(masked_psnr(&a, &b, 3, &[false, false]), Err(MetricError::Empty { .. })));
        assert!(matches!(masked_psnr(&a, &b, 3, &[true]), Err(MetricError::LengthMismatch { .. })));
    }

    #[test]
    fn identical_and_clamped_images() {
        let shape = ImageShape::new(8, 9, 3);
        let a: Vec<f32> = (0..shape.len()).map(|i| (i % 17) as f32 / 16.0).collect();
        assert_eq!(psnr(&a, &a).unwrap(), f64::INFINITY);
        let s = ssim(&a, &a, shape).unwrap();
        assert!((s.value - 1.0).abs() < 1e-12 && s.per_channel.len() == 3);
        // Values outside [0, 1] are clamped first.
        let b: Vec<f32> = a
            .iter()
            .map(|v| {
                if *v == 1.0 {
                    3.0
                } else if *v == 0.0 {
                    -2.0
                } else {
                    *v
                }
            })
            .collect();
        assert_eq!(psnr(&a, &b).unwrap(), f64::INFINITY);
        // MSE 0.01 -> 20 dB.
        let zeros = vec![0.0f32; 12];
        let tenth = vec![0.1f32; 12];
        assert!((psnr(&zeros, &tenth).unwrap() - 20.0).abs() < 1e-5);
    }

    #[test]
    fn uniform_filter_of_a_constant_is_the_constant() {
        let plane = vec![0.25; 7 * 10];
        assert!(uniform_filter(&plane, 7, 10).iter().all(|v| (v - 0.25).abs() < 1e-15));
    }

    #[test]
    fn bad_sizes_are_errors() {
        let a = vec![0.5f32; 6 * 6 * 3];
        assert!(ssim(&a, &a, ImageShape::new(6, 6, 3)).is_err());
        assert!(ssim(&a, &a[1..], ImageShape::new(6, 6, 3)).is_err());
        assert!(psnr(&a, &a[1..]).is_err());
        assert!(psnr(&[], &[]).is_err());
    }
}
