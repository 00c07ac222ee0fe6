//! The sky model: a fixed hemisphere of Gaussians far from the cameras whose colours are read from the input
//! images, rendered as the background.
//!
//! Its state is the release's buffers (Fibonacci-hemisphere points `bg_pcd` at the configured radius, log
//! scales `bg_scales`, opacities `bg_opacity`, wxyz rotations `bg_quat`) and the colour field `bg_field`
//! (`Linear 3 -> 64`, ReLU, `Linear 64 -> 6`, tanh). Colouring, as the release computes it: project every
//! point into every view (`K [R | t] X`, pixel = `xy / max(z, 1e-8)` clamped to +-1e6); a view sees a point
//! when `z > 0` and the pixel lies in `[0, W-1] x [0, H-1]`; sample the `[0, 1]` image bilinearly with zero
//! padding at the point (quirk: coordinates are normalised by `W - 1` / `H - 1` but sampled with
//! `align_corners = False`, i.e. at `pixel * W / (W - 1) - 0.5`); average over the views that see it; keep the
//! points seen at least once; the field's first three outputs are the colours (tanh, so possibly negative).
//! Scales are `exp(bg_scales)` (the release zeroes its residual). The projection runs on the host in `f64`.

use burn::module::{Module, Param};
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics};
use rstar::RTree;
use rstar::primitives::GeomWithData;

use crate::config::SkyConfig;

/// Pixel coordinates are clamped to this magnitude.
const PIXEL_LIMIT: f64 = 1e6;
/// Depths are clamped from below before the perspective division.
const MIN_DEPTH: f64 = 1e-8;

/// The colour field `bg_field`.
#[derive(Module, Debug)]
pub struct BackgroundField {
    pub layers: Vec<Linear>,
}

impl BackgroundField {
    /// Channels of the output.
    pub fn output_width(&self) -> usize {
        self.layers.last().map_or(0, |layer| layer.weight.dims()[1])
    }

    /// `[N, 3]` mean RGB -> `[N, 6]` in (-1, 1).
    pub fn forward(&self, rgb: Tensor<2>) -> Tensor<2> {
        self.layers[1].forward(relu(self.layers[0].forward(rgb))).tanh()
    }
}

#[derive(Module, Debug)]
pub struct SkyModel {
    /// `[N, 3]` log scales.
    pub bg_scales: Param<Tensor<2>>,
    /// `[N, 3]` points.
    pub bg_pcd: Param<Tensor<2>>,
    /// `[N, 1]`.
    pub bg_opacity: Param<Tensor<2>>,
    /// `[N, 4]` wxyz.
    pub bg_quat: Param<Tensor<2>>,
    pub bg_field: BackgroundField,
}

/// Where every sky point lands in every view; arrays are view-major, `[views * points]`.
#[derive(Debug, Clone)]
pub struct SkyProjection {
    pub points: usize,
    /// Clamped pixel coordinates `(x, y)`.
    pub pixels: Vec<[f64; 2]>,
    /// Camera-space depth.
    pub depth: Vec<f64>,
    /// In front of the camera and inside the image.
    pub seen: Vec<bool>,
}

/// The sky Gaussians kept for rendering (the points seen by at least one view).
#[derive(Debug, Clone)]
pub struct SkyGaussians {
    /// Indices of the kept points in the hemisphere.
    pub visible_index: Vec<usize>,
    /// `[V, 3]` mean colour sampled from the views that see each point.
    pub rgb_mean: Tensor<2>,
    /// `[V, 6]` colour field output.
    pub field_out: Tensor<2>,
    /// `[V, 3]` colours (tanh, may be negative).
    pub colors: Tensor<2>,
    /// `[V, 3]`.
    pub means: Tensor<2>,
    /// `[V, 3]` linear scales.
    pub scales: Tensor<2>,
    /// `[V, 4]` wxyz.
    pub quats: Tensor<2>,
    /// `[V]`.
    pub opacities: Tensor<1>,
}

fn host(t: Tensor<2>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32 tensor")
}

impl SkyModel {
    /// Placeholder buffers for `resolution^2` points; load them from a checkpoint.
    pub fn new(config: &SkyConfig, device: &Device) -> Self {
        let n = config.resolution * config.resolution;
        let buffer = |width: usize| Initializer::Zeros.init([n, width], device).set_require_grad(false);
        Self {
            bg_scales: buffer(3),
            bg_pcd: buffer(3),
            bg_opacity: buffer(1),
            bg_quat: buffer(4),
            bg_field: BackgroundField {
                layers: vec![LinearConfig::new(3, 64).init(device), LinearConfig::new(64, 6).init(device)],
            },
        }
    }

    /// The buffers a fresh model starts from: [`hemisphere_points`] at `config.radius`, isotropic log scales
    /// from [`neighbour_log_scales`], opacity one, identity rotations. A checkpoint overwrites them.
    pub fn initialised(config: &SkyConfig, device: &Device) -> Self {
        let points = hemisphere_points(config.resolution * config.resolution, config.radius);
        let n = points.len();
        let scales = neighbour_log_scales(&points);
        let tensor = |values: Vec<f32>, width: usize| {
            Param::from_tensor(Tensor::<2>::from_data(TensorData::new(values, [n, width]), device))
                .set_require_grad(false)
        };
        Self {
            bg_pcd: tensor(points.iter().flat_map(|p| p.map(|v| v as f32)).collect(), 3),
            bg_scales: tensor(scales.iter().flat_map(|&s| [s as f32; 3]).collect(), 3),
            bg_opacity: tensor(vec![1.0; n], 1),
            bg_quat: tensor((0..n).flat_map(|_| [1.0, 0.0, 0.0, 0.0]).collect(), 4),
            ..Self::new(config, device)
        }
    }

    /// Projects every point into every view.
    pub fn project(&self, views: &[(CameraFromWorld, PinholeIntrinsics)], size: ImageSize) -> SkyProjection {
        let points: Vec<f32> = host(self.bg_pcd.val());
        let n = points.len() / 3;
        let (max_x, max_y) = (size.width as f64 - 1.0, size.height as f64 - 1.0);
        let mut projection = SkyProjection { points: n, pixels: vec![], depth: vec![], seen: vec![] };
        for (camera_from_world, k) in views {
            let m = k.matrix();
            for p in points.chunks(3) {
                let x = camera_from_world.transform_point([p[0], p[1], p[2]].map(f64::from).into());
                let h = m * x;
                let z = h.z.max(MIN_DEPTH);
                let pixel = [(h.x / z).clamp(-PIXEL_LIMIT, PIXEL_LIMIT), (h.y / z).clamp(-PIXEL_LIMIT, PIXEL_LIMIT)];
                let inside = (0.0..=max_x).contains(&pixel[0]) && (0.0..=max_y).contains(&pixel[1]);
                projection.seen.push(h.z > 0.0 && inside);
                projection.pixels.push(pixel);
                projection.depth.push(h.z);
            }
        }
        projection
    }

    /// Colours the points from `images` (`[views, 3, H, W]` RGB in `[0, 1]`) seen from `views`.
    pub fn gaussians(&self, images: Tensor<4>, views: &[(CameraFromWorld, PinholeIntrinsics)]) -> SkyGaussians {
        let [num_views, channels, height, width] = images.dims();
        assert_eq!(num_views, views.len(), "one camera per image");
        assert_eq!(channels, 3, "RGB images");
        let device = images.device();
        let size = ImageSize::new(width as u32, height as u32).expect("non-empty images");
        let projection = self.project(views, size);
        let pixels: Vec<f32> = images.into_data().try_to_vec::<f32>().expect("f32 images");
        let n = projection.points;

        let mut visible_index = vec![];
        let mut rgb_mean = vec![];
        for point in 0..n {
            let mut sum = [0.0f64; 3];
            let mut count = 0usize;
            for view in 0..num_views {
                let i = view * n + point;
                if !projection.seen[i] {
                    continue;
                }
                count += 1;
                let image = &pixels[view * 3 * height * width..][..3 * height * width];
                let grid = grid_coordinates(projection.pixels[i], size);
                let sample = sample_bilinear_zeros(image, [height, width], grid);
                sum.iter_mut().zip(sample).for_each(|(s, v)| *s += v);
            }
            if count > 0 {
                visible_index.push(point);
                rgb_mean.extend(sum.map(|s| (s / count as f64) as f32));
            }
        }
        let v = visible_index.len();
        if v == 0 {
            // No point is seen by any view: an empty set, made without running kernels on zero-sized tensors
            // (burn's CubeCL backends fail on some of them).
            let empty = |width: usize| Tensor::<2>::from_data(TensorData::new(Vec::<f32>::new(), [0, width]), &device);
            let field_width = self.bg_field.output_width();
            return SkyGaussians {
                visible_index,
                rgb_mean: empty(3),
                field_out: empty(field_width),
                colors: empty(3),
                means: empty(3),
                scales: empty(3),
                quats: empty(4),
                opacities: Tensor::<1>::from_data(TensorData::new(Vec::<f32>::new(), [0]), &device),
            };
        }
        let gather = |buffer: &Param<Tensor<2>>| {
            let width = buffer.dims()[1];
            let values = host(buffer.val());
            let kept: Vec<f32> =
                visible_index.iter().flat_map(|&i| values[i * width..(i + 1) * width].to_vec()).collect();
            Tensor::<2>::from_data(TensorData::new(kept, [v, width]), &device)
        };
        let rgb_mean = Tensor::<2>::from_data(TensorData::new(rgb_mean, [v, 3]), &device);
        let field_out = self.bg_field.forward(rgb_mean.clone());
        SkyGaussians {
            colors: field_out.clone().narrow(1, 0, 3),
            field_out,
            rgb_mean,
            means: gather(&self.bg_pcd),
            scales: gather(&self.bg_scales).exp(),
            quats: gather(&self.bg_quat),
            opacities: gather(&self.bg_opacity).reshape([v]),
            visible_index,
        }
    }
}

/// The release's sampling-grid coordinates of pixel `(x, y)`: `2 p / (W - 1, H - 1) - 1`, i.e. normalised as
/// for `align_corners = True` (the sampler reads them with `align_corners = False`).
pub fn grid_coordinates([x, y]: [f64; 2], size: ImageSize) -> [f64; 2] {
    [2.0 * x / (size.width as f64 - 1.0) - 1.0, 2.0 * y / (size.height as f64 - 1.0) - 1.0]
}

/// Bilinear sample of a `[3, H, W]` image at grid coordinates `(gx, gy)` in `[-1, 1]`, read with
/// `align_corners = False` (pixel `((g + 1) W - 1) / 2`), taps outside the image counting as zero.
fn sample_bilinear_zeros(image: &[f32], [height, width]: [usize; 2], [gx, gy]: [f64; 2]) -> [f64; 3] {
    let ix = ((gx + 1.0) * width as f64 - 1.0) / 2.0;
    let iy = ((gy + 1.0) * height as f64 - 1.0) / 2.0;
    let (x0, y0) = (ix.floor(), iy.floor());
    let (fx, fy) = (ix - x0, iy - y0);
    let mut out = [0.0; 3];
    for (dy, wy) in [(0.0, 1.0 - fy), (1.0, fy)] {
        for (dx, wx) in [(0.0, 1.0 - fx), (1.0, fx)] {
            let (tx, ty) = (x0 + dx, y0 + dy);
            if tx < 0.0 || ty < 0.0 || tx >= width as f64 || ty >= height as f64 {
                continue;
            }
            let cell = ty as usize * width + tx as usize;
            for (c, o) in out.iter_mut().enumerate() {
                *o += wx * wy * image[c * height * width + cell] as f64;
            }
        }
    }
    out
}

/// `count` points of a Fibonacci lattice on the upper hemisphere (`y` in `[-1, 0]`: up is `-y` in OpenCV axes)
/// of `radius`: point `i` has `y = -1 + i / (count - 1)` and azimuth `i` golden angles (`π (3 - √5)`) from `+x`
/// towards `+z`.
pub fn hemisphere_points(count: usize, radius: f64) -> Vec<[f64; 3]> {
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..count)
        .map(|i| {
            let y = if count > 1 { -1.0 + i as f64 / (count - 1) as f64 } else { -1.0 };
            let ring = (1.0 - y * y).max(0.0).sqrt();
            let azimuth = golden_angle * i as f64;
            [ring * azimuth.cos() * radius, y * radius, ring * azimuth.sin() * radius]
        })
        .collect()
}

/// Log of each point's mean distance to its three nearest other points (isotropic sky scales), found with an
/// R*-tree: the full-size hemisphere holds tens of thousands of points, which a search of every pair took tens
/// of seconds over. Each distance is `sqrt(dx² + dy² + dz²)` of the point and a neighbour, summed nearest first.
pub fn neighbour_log_scales(points: &[[f64; 3]]) -> Vec<f64> {
    let tree = RTree::bulk_load(points.iter().enumerate().map(|(i, p)| GeomWithData::new(*p, i)).collect());
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut nearest: Vec<f64> = tree
                .nearest_neighbor_iter(*p)
                .filter(|other| other.data != i)
                .take(3)
                .map(|other| distance(p, other.geom()))
                .collect();
            nearest.sort_by(f64::total_cmp);
            log_mean(&nearest)
        })
        .collect()
}

/// Log of the mean of `distances` (nearest first), kept above the smallest positive float; with no distance, that
/// smallest float's log.
fn log_mean(distances: &[f64]) -> f64 {
    (distances.iter().sum::<f64>() / distances.len().max(1) as f64).max(f64::MIN_POSITIVE).ln()
}

/// The Euclidean distance between two points.
fn distance(p: &[f64; 3], q: &[f64; 3]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The three nearest other points of each point by a search of every pair: the reference the tree is held to.
    fn neighbour_log_scales_of_every_pair(points: &[[f64; 3]]) -> Vec<f64> {
        let log_mean = |i: usize| {
            let mut others: Vec<f64> =
                points.iter().enumerate().filter(|&(j, _)| j != i).map(|(_, q)| distance(&points[i], q)).collect();
            others.sort_by(f64::total_cmp);
            log_mean(&others[..others.len().min(3)])
        };
        (0..points.len()).map(log_mean).collect()
    }

    #[test]
    fn neighbour_scales_match_a_search_of_every_pair() {
        let hemisphere = hemisphere_points(700, 50.0);
        assert_eq!(neighbour_log_scales(&hemisphere), neighbour_log_scales_of_every_pair(&hemisphere));
        // Repeated points (distance 0, clamped before the log), a lone pair and a single point.
        let repeated = [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [4.0, 0.0, 0.0], [-2.0, 1.0, 0.5]];
        assert_eq!(neighbour_log_scales(&repeated), neighbour_log_scales_of_every_pair(&repeated));
        let pair = [[0.0, 0.0, 0.0], [0.0, 3.0, 4.0]];
        assert_eq!(neighbour_log_scales(&pair), vec![5f64.ln(); 2]);
        assert_eq!(neighbour_log_scales(&[[1.0, 1.0, 1.0]]), vec![f64::MIN_POSITIVE.ln()]);
    }

    #[test]
    fn sampling_reads_pixels_at_the_release_offset() {
        // 2x3 image, channel value = column index; x = 0 maps to 0 * 3 / 2 - 0.5 = -0.5: half the first pixel.
        let image: Vec<f32> = (0..3).flat_map(|_| (0..2).flat_map(|_| [0.0, 1.0, 2.0])).collect();
        let size = ImageSize::new(3, 2).unwrap();
        let s = sample_bilinear_zeros(&image, [2, 3], grid_coordinates([0.0, 0.0], size));
        assert!((s[0] - 0.0).abs() < 1e-12);
        // (x, y) = (2, 1), the last pixel, maps to (2.5, 1.5): a quarter of pixel (2, 1), the other taps outside.
        let s = sample_bilinear_zeros(&image, [2, 3], grid_coordinates([2.0, 1.0], size));
        assert!((s[1] - 0.5).abs() < 1e-12, "{s:?}");
    }
}
