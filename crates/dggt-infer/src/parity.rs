//! Parity with the release: a folder of reference vectors (`config.json`, `weights.safetensors` or
//! `weights.pt`, `inputs.safetensors`, `outputs.safetensors`) is opened, the network its `config.json`
//! describes is built, loaded and run on its inputs, and every reference output is compared with the port's.
//!
//! The outputs compared are the names found in `outputs.safetensors`; `OUTPUTS` is the one table saying how
//! each name is reproduced (from the forward pass, the cameras decoded from it, the Gaussian means unprojected
//! from its depth, the sky model coloured with those cameras, the lifespan decay, or the scene rendered from
//! all of these). A name the table does not know is reported
//! as not compared, never dropped.
//!
//! Tolerance: `max(1e-4, 1e-4 * max|reference|)` on the largest absolute difference. Two outputs are compared
//! on a well-conditioned part: `gs_conf = 1 / (relu(x) + 1e-6)` through its reciprocal (a 1e-6 error in `x`
//! near 0 is a huge error in `gs_conf`), and sky pixel locations only where the point is seen (in front of the
//! camera and inside the image: behind it the release's values are clamped garbage, at grazing depths `x / z`
//! amplifies the reference's `f32` rounding).
//!
//! Rendered images (`render.fg_*`, `render.sky_*`, `render.final_rgb`) are compared pixel by pixel: they pass
//! when at least [`RENDER_PIXEL_FRACTION`] of the pixels are within tolerance on every channel. Rasterisers
//! differ in accumulation order, so a pixel whose transmittance crosses the 1e-4 stop, or a Gaussian whose
//! alpha crosses 1/255, on one side only can legitimately differ; the row's note gives the fraction.

use std::cell::OnceCell;
use std::fmt;
use std::path::{Path, PathBuf};

use burn::tensor::activation::sigmoid;
use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::{CameraFromWorld, ImageSize, PinholeIntrinsics, PixelConvention, PoseEncoding, unproject_depth_map};
use safetensors::{Dtype, SafeTensors};

use dggt_model::dpt::{DptOutput, DptPrediction};
use dggt_model::lifespan::{dynamic_opacity, frame_times, opacity_at, static_opacity};
use dggt_model::sky::{SkyGaussians, SkyProjection, grid_coordinates};
use dggt_model::weights::LoadReport;
use dggt_model::{Dggt, DggtOutput, GaussianOutput, ModelConfig, ModelError};

use crate::release::{SceneInputs, SceneRender, render_scene};

/// Absolute tolerance, and tolerance relative to a reference tensor's largest magnitude.
pub const TOLERANCE: f32 = 1e-4;

/// The fraction of a rendered image's pixels that must be within tolerance.
pub const RENDER_PIXEL_FRACTION: f64 = 0.999;

/// The files of a vector folder; the weights may be either of [`WEIGHT_FILES`].
pub const VECTOR_FILES: [&str; 3] = ["config.json", "inputs.safetensors", "outputs.safetensors"];

/// Weight files looked for in a vector folder, in order of preference.
pub const WEIGHT_FILES: [&str; 2] = ["weights.safetensors", "weights.pt"];

/// A tensor on the host: row-major values and a shape.
#[derive(Debug, Clone, PartialEq)]
pub struct HostTensor {
    pub shape: Vec<usize>,
    pub values: Vec<f32>,
}

impl HostTensor {
    pub fn new(shape: Vec<usize>, values: Vec<f32>) -> Self {
        assert_eq!(shape.iter().product::<usize>(), values.len(), "{shape:?} does not hold {} values", values.len());
        Self { shape, values }
    }

    pub fn from_tensor<const D: usize>(tensor: Tensor<D>) -> Self {
        let shape = tensor.dims().to_vec();
        let values = tensor.into_data().convert::<f32>().try_into_vec::<f32>().expect("converted to f32");
        Self { shape, values }
    }

    /// The tensor on `device`, or `None` when it does not have `D` dimensions.
    pub fn to_tensor<const D: usize>(&self, device: &Device) -> Option<Tensor<D>> {
        let shape: [usize; D] = self.shape.clone().try_into().ok()?;
        Some(Tensor::from_data(TensorData::new(self.values.clone(), shape), device))
    }

    pub fn max_abs(&self) -> f32 {
        self.values.iter().fold(0.0f32, |m, v| m.max(v.abs()))
    }
}

/// Every tensor of a safetensors file in file order, as `f32` (floating-point, integer and boolean tensors
/// are converted).
pub fn read_safetensors(path: impl AsRef<Path>) -> Result<Vec<(String, HostTensor)>, ModelError> {
    let path = path.as_ref();
    let error = |message: String| ModelError::Vectors { path: path.display().to_string(), message };
    let bytes = std::fs::read(path).map_err(|source| ModelError::Io { path: path.display().to_string(), source })?;
    let file = SafeTensors::deserialize(&bytes).map_err(|e| error(e.to_string()))?;
    let (_, metadata) = SafeTensors::read_metadata(&bytes).map_err(|e| error(e.to_string()))?;
    metadata
        .offset_keys()
        .into_iter()
        .map(|name| {
            let view = file.tensor(&name).map_err(|e| error(e.to_string()))?;
            let data = view.data();
            let values: Vec<f32> = match view.dtype() {
                Dtype::F32 => data.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect(),
                Dtype::F64 => data.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap()) as f32).collect(),
                Dtype::I64 => data.chunks_exact(8).map(|b| i64::from_le_bytes(b.try_into().unwrap()) as f32).collect(),
                Dtype::I32 => data.chunks_exact(4).map(|b| i32::from_le_bytes(b.try_into().unwrap()) as f32).collect(),
                Dtype::U8 | Dtype::BOOL => data.iter().map(|&b| b as f32).collect(),
                other => return Err(error(format!("tensor {name} has unsupported dtype {other:?}"))),
            };
            Ok((name, HostTensor::new(view.shape().to_vec(), values)))
        })
        .collect()
}

/// A folder of reference vectors, read into memory (weights excepted: they are loaded into the network).
#[derive(Debug, Clone)]
pub struct ParityVectors {
    pub dir: PathBuf,
    pub config: ModelConfig,
    pub inputs: Vec<(String, HostTensor)>,
    /// In file order.
    pub outputs: Vec<(String, HostTensor)>,
}

impl ParityVectors {
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, ModelError> {
        let dir = dir.as_ref();
        let error = |message: String| ModelError::Vectors { path: dir.display().to_string(), message };
        if !dir.is_dir() {
            return Err(error("no such folder".into()));
        }
        if let Some(missing) = VECTOR_FILES.iter().find(|file| !dir.join(file).is_file()) {
            return Err(error(format!(
                "{missing} is missing (a vector folder holds {}, and {} or {})",
                VECTOR_FILES.join(", "),
                WEIGHT_FILES[0],
                WEIGHT_FILES[1]
            )));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            config: ModelConfig::from_parity_json(dir.join("config.json"))?,
            inputs: read_safetensors(dir.join("inputs.safetensors"))?,
            outputs: read_safetensors(dir.join("outputs.safetensors"))?,
        })
    }

    /// The first of [`WEIGHT_FILES`] present in the folder.
    pub fn default_weights(&self) -> Result<PathBuf, ModelError> {
        WEIGHT_FILES.iter().map(|file| self.dir.join(file)).find(|path| path.is_file()).ok_or_else(|| {
            ModelError::Vectors {
                path: self.dir.display().to_string(),
                message: format!("no weights: neither {} nor {}", WEIGHT_FILES[0], WEIGHT_FILES[1]),
            }
        })
    }

    pub fn input(&self, name: &str) -> Option<&HostTensor> {
        self.inputs.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }

    pub fn output(&self, name: &str) -> Option<&HostTensor> {
        self.outputs.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }

    /// The `images` input, `[B, S, 3, H, W]` RGB in `[0, 1]`.
    pub fn images(&self, device: &Device) -> Result<Tensor<5>, ModelError> {
        let error =
            |message: &str| ModelError::Vectors { path: self.dir.display().to_string(), message: message.into() };
        let images = self.input("images").ok_or_else(|| error("inputs.safetensors has no `images`"))?;
        images.to_tensor(device).ok_or_else(|| error("`images` is not [B, S, 3, H, W]"))
    }
}

/// The outcome of one comparison.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    Pass,
    Fail,
    /// Not compared, with the reason.
    Skipped(String),
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Status::Pass => f.pad("pass"),
            Status::Fail => f.pad("FAIL"),
            Status::Skipped(reason) => f.pad(&format!("not compared ({reason})")),
        }
    }
}

/// One reference output and how the port's value compares with it.
#[derive(Debug, Clone, PartialEq)]
pub struct ParityRow {
    pub name: String,
    /// The reference's shape.
    pub shape: Vec<usize>,
    /// Largest absolute difference over the compared elements.
    pub max_abs: Option<f32>,
    /// `max_abs` relative to the largest compared reference magnitude.
    pub max_rel: Option<f32>,
    /// The largest `max_abs` that passes.
    pub tolerance: Option<f32>,
    pub status: Status,
    /// How the tensor was compared when not elementwise, or why it failed other than by tolerance.
    pub note: Option<String>,
}

impl ParityRow {
    fn without_values(name: &str, reference: &HostTensor, status: Status, note: Option<String>) -> Self {
        Self {
            name: name.to_string(),
            shape: reference.shape.clone(),
            max_abs: None,
            max_rel: None,
            tolerance: None,
            status,
            note,
        }
    }
}

/// Every reference output of one run.
#[derive(Debug, Clone)]
pub struct ParityReport {
    pub weights: PathBuf,
    pub load: LoadReport,
    pub rows: Vec<ParityRow>,
}

impl ParityReport {
    /// No compared output is out of tolerance.
    pub fn passed(&self) -> bool {
        self.failed().next().is_none()
    }

    pub fn failed(&self) -> impl Iterator<Item = &ParityRow> {
        self.rows.iter().filter(|row| row.status == Status::Fail)
    }

    pub fn row(&self, name: &str) -> Option<&ParityRow> {
        self.rows.iter().find(|row| row.name == name)
    }

    /// One line: how many outputs passed, failed and were not compared.
    pub fn summary(&self) -> String {
        let count = |f: fn(&Status) -> bool| self.rows.iter().filter(|row| f(&row.status)).count();
        format!(
            "{} outputs: {} pass, {} fail, {} not compared",
            self.rows.len(),
            count(|s| *s == Status::Pass),
            count(|s| *s == Status::Fail),
            count(|s| matches!(s, Status::Skipped(_)))
        )
    }
}

impl fmt::Display for ParityReport {
    /// The table: name, shape, max abs error, max relative error, tolerance, status (and note).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let shapes: Vec<String> = self.rows.iter().map(|row| format!("{:?}", row.shape)).collect();
        let name_width = self.rows.iter().map(|row| row.name.len()).chain([6]).max().unwrap_or(6);
        let shape_width = shapes.iter().map(String::len).chain([5]).max().unwrap_or(5);
        let number = |value: Option<f32>| value.map_or_else(|| "-".to_string(), |v| format!("{v:.3e}"));
        writeln!(
            f,
            "{:<name_width$}  {:<shape_width$}  {:>11}  {:>11}  {:>11}  status",
            "output", "shape", "max abs err", "max rel err", "tolerance"
        )?;
        for (row, shape) in self.rows.iter().zip(&shapes) {
            write!(
                f,
                "{:<name_width$}  {shape:<shape_width$}  {:>11}  {:>11}  {:>11}  {}",
                row.name,
                number(row.max_abs),
                number(row.max_rel),
                number(row.tolerance),
                row.status
            )?;
            match &row.note {
                Some(note) => writeln!(f, "  ({note})")?,
                None => writeln!(f)?,
            }
        }
        Ok(())
    }
}

/// The shared parity vectors' folder `name` (e.g. `dggt_tiny_s3_56x70`): under `$DGGT_PARITY_DIR` when set,
/// else under `../shared/parity` of the nearest ancestor of `start` (a crate's manifest folder) that has one.
/// Panics, naming where it looked, when the folder has no `config.json`: for tests, which need the vectors.
pub fn parity_folder(start: &Path, name: &str) -> PathBuf {
    let root = match std::env::var_os("DGGT_PARITY_DIR") {
        Some(dir) => PathBuf::from(dir),
        None => start
            .ancestors()
            .map(|dir| dir.join("../shared/parity"))
            .find(|dir| dir.is_dir())
            .unwrap_or_else(|| start.join("../shared/parity")),
    };
    let dir = root.join(name);
    assert!(
        dir.join("config.json").is_file(),
        "parity vectors not found at {} (set DGGT_PARITY_DIR to the shared parity folder)",
        dir.display()
    );
    dir
}

/// Builds the network of `vectors`, loads `weights`, runs it on the vectors' images on `device` and compares
/// every reference output.
pub fn run_parity(vectors: &ParityVectors, weights: &Path, device: &Device) -> Result<ParityReport, ModelError> {
    let (model, load) = Dggt::from_checkpoint(&vectors.config, weights, device)?;
    let images = vectors.images(device)?;
    let out = model.forward(images.clone())?;
    let mut prediction = Prediction::new(&model, images, out);
    prediction.sky_mask = vectors.input("sky_mask").cloned();
    let rows = vectors.outputs.iter().map(|(name, reference)| prediction.compare(name, reference)).collect();
    Ok(ParityReport { weights: weights.to_path_buf(), load, rows })
}

/// The port's value of a reference output.
struct Actual {
    tensor: HostTensor,
    /// Only these elements are compared (all when `None`).
    mask: Option<Vec<bool>>,
    /// Both sides pass through this before comparing.
    map: Option<fn(f32) -> f32>,
    note: Option<&'static str>,
    /// Compared as an image with this many channels per pixel (see [`RENDER_PIXEL_FRACTION`]).
    pixel_channels: Option<usize>,
}

fn dense<const D: usize>(tensor: Tensor<D>) -> Actual {
    host(HostTensor::from_tensor(tensor))
}

fn host(tensor: HostTensor) -> Actual {
    Actual { tensor, mask: None, map: None, note: None, pixel_channels: None }
}

/// A rendered image, compared pixel by pixel.
fn image<const D: usize>(tensor: Tensor<D>, channels: usize) -> Actual {
    Actual { pixel_channels: Some(channels), ..dense(tensor) }
}

type Extract = fn(&Prediction, &Key) -> Result<Actual, String>;

/// How one reference output is reproduced.
#[derive(Clone, Copy)]
enum Rule {
    Compare(Extract),
}

/// What a name matched in its pattern: the `{i}` index and the `{head}` name.
struct Key<'a> {
    index: usize,
    head: &'a str,
}

/// The DPT heads a `{head}` pattern segment matches.
const DPT_HEADS: [&str; 5] = ["depth_head", "point_head", "gs_head", "instance_head", "semantic_head"];

/// Reference output name patterns and how each is reproduced. In a pattern, `{i}` matches an index, `{head}`
/// one of the DPT heads, and a final `{rest}` any further segments.
const OUTPUTS: &[(&str, Rule)] = &[
    // DINO patch embedding.
    (
        "dino.pos_embed_interp",
        Rule::Compare(|p, _| {
            let [_, _, _, height, width] = p.images.dims();
            Ok(dense(p.model.aggregator.patch_embed.interpolated_pos_embed(height, width)))
        }),
    ),
    ("dino.prepared_tokens", Rule::Compare(|p, _| Ok(dense(p.out.aggregator.dino.prepared_tokens.clone())))),
    (
        "image_feature",
        Rule::Compare(|p, _| {
            let last = p.out.aggregator.dino.layers.last().ok_or("DINO has no layers")?.clone();
            let [batch, frames, ..] = p.images.dims();
            let [rows, cols] = p.out.aggregator.grid;
            let channels = last.dims()[2];
            Ok(dense(last.reshape([batch, frames, rows, cols, channels])))
        }),
    ),
    // Aggregator.
    ("agg.output_list.{i}", Rule::Compare(|p, k| Ok(dense(layer(&p.out.aggregator.output_list, k.index)?)))),
    (
        "agg.output_list_with_tokens.{i}",
        Rule::Compare(|p, k| {
            layer(&p.out.aggregator.output_list, k.index)?;
            Ok(dense(p.out.aggregator.output_with_dino_tokens(k.index)))
        }),
    ),
    ("agg.dino_token_list.{i}", Rule::Compare(|p, k| Ok(dense(layer(&p.out.aggregator.dino_token_list, k.index)?)))),
    (
        "agg.patch_start_idx",
        Rule::Compare(|p, _| Ok(host(HostTensor::new(vec![1], vec![p.out.aggregator.patch_start_idx as f32])))),
    ),
    // Camera head.
    (
        "camera.token_norm_out",
        Rule::Compare(|p, _| {
            let last = p.out.aggregator.output_list.last().ok_or("the aggregator has no layers")?.clone();
            Ok(dense(p.model.camera_head.token_norm_out(last)))
        }),
    ),
    ("camera.pose_deltas", Rule::Compare(|p, _| Ok(dense(Tensor::stack::<4>(p.out.camera.deltas.clone(), 0))))),
    ("camera.pose_preact", Rule::Compare(|p, _| Ok(dense(Tensor::stack::<4>(p.out.camera.preactivations.clone(), 0))))),
    ("camera.pose_enc_list", Rule::Compare(|p, _| Ok(dense(Tensor::stack::<4>(p.out.camera.encodings.clone(), 0))))),
    ("camera.pose_enc_iter.{i}", Rule::Compare(|p, k| Ok(dense(layer(&p.out.camera.encodings, k.index)?)))),
    ("pose_enc", Rule::Compare(|p, _| Ok(dense(p.out.camera.pose_encoding())))),
    // DPT internals and raw outputs.
    ("dbg.{head}.resize.{i}", Rule::Compare(|p, k| Ok(dense(layer(&p.dpt(k.head)?.resized, k.index)?)))),
    ("dbg.{head}.output_conv1", Rule::Compare(|p, k| Ok(dense(p.dpt(k.head)?.fused.clone())))),
    ("dbg.{head}.head_in", Rule::Compare(|p, k| Ok(dense(p.dpt(k.head)?.head_in.clone())))),
    ("{head}.raw", Rule::Compare(|p, k| Ok(dense(p.dpt(k.head)?.raw.clone())))),
    // Depth and point heads.
    ("depth", Rule::Compare(|p, _| Ok(dense(p.out.depth.prediction.clone())))),
    ("depth_conf", Rule::Compare(|p, _| Ok(dense(p.out.depth.confidence.clone())))),
    ("world_points", Rule::Compare(|p, _| Ok(dense(p.points()?.prediction.clone())))),
    ("world_points_conf", Rule::Compare(|p, _| Ok(dense(p.points()?.confidence.clone())))),
    // Gaussian head.
    ("gs_map", Rule::Compare(|p, _| Ok(dense(p.gaussians()?.maps.gs_map())))),
    (
        "gs_conf",
        Rule::Compare(|p, _| {
            let mut actual = dense(p.gaussians()?.maps.lifespan.clone());
            actual.map = Some(f32::recip);
            actual.note = Some("compared as 1/gs_conf");
            Ok(actual)
        }),
    ),
    ("gs.rgb", Rule::Compare(|p, _| Ok(dense(p.gaussians()?.maps.rgb.clone())))),
    ("gs.opacity", Rule::Compare(|p, _| Ok(dense(p.gaussians()?.maps.opacity.clone())))),
    ("gs.scale", Rule::Compare(|p, _| Ok(dense(p.gaussians()?.maps.scale.clone())))),
    ("gs.rotation", Rule::Compare(|p, _| Ok(dense(p.gaussians()?.maps.rotation.clone())))),
    ("gs.lifespan_raw", Rule::Compare(|p, _| Ok(dense(p.gaussians()?.maps.lifespan_raw.clone())))),
    // Instance (dynamic) and semantic heads.
    ("dynamic_conf", Rule::Compare(|p, _| Ok(dense(p.instance()?.prediction.clone())))),
    ("instance.logit", Rule::Compare(|p, _| Ok(dense(p.dynamic_logit()?)))),
    ("instance.prob", Rule::Compare(|p, _| Ok(dense(sigmoid(p.dynamic_logit()?))))),
    ("instance.conf_unused", Rule::Compare(|p, _| Ok(dense(p.instance()?.confidence.clone())))),
    ("semantic_logits", Rule::Compare(|p, _| Ok(dense(p.semantic()?.prediction.clone())))),
    // Cameras decoded from the pose encoding, and the Gaussian means.
    (
        "extrinsics",
        Rule::Compare(|p, _| {
            let values = p.cameras()?.iter().flat_map(|(c, _)| c.to_rows_3x4_f32()).flatten().collect();
            Ok(host(HostTensor::new(p.per_frame(&[3, 4]), values)))
        }),
    ),
    (
        "intrinsics",
        Rule::Compare(|p, _| {
            let values = p.cameras()?.iter().flat_map(|(_, k)| k.to_rows_f32()).flatten().collect();
            Ok(host(HostTensor::new(p.per_frame(&[3, 3]), values)))
        }),
    ),
    (
        "extrinsic_4x4",
        Rule::Compare(|p, _| {
            let [_, frames, ..] = p.images.dims();
            let first: Vec<f32> =
                p.cameras()?[..frames].iter().flat_map(|(c, _)| c.to_rows()).flatten().map(|v| v as f32).collect();
            Ok(host(HostTensor::new(vec![frames, 4, 4], first)))
        }),
    ),
    ("means.cam", Rule::Compare(|p, _| p.means(false))),
    ("means.world", Rule::Compare(|p, _| p.means(true))),
    // Sky model.
    (
        "sky.pixel_locations",
        Rule::Compare(|p, _| {
            let (projection, _) = p.sky()?;
            let values = projection.pixels.iter().flatten().map(|&v| v as f32).collect();
            let mask = projection.seen.iter().flat_map(|&seen| [seen; 2]).collect();
            Ok(p.sky_pixels(values, mask))
        }),
    ),
    (
        "sky.normalized_pixel_locations",
        Rule::Compare(|p, _| {
            let (projection, _) = p.sky()?;
            let values =
                projection.pixels.iter().flat_map(|&pixel| grid_coordinates(pixel, p.size)).map(|v| v as f32).collect();
            let mask = projection.seen.iter().flat_map(|&seen| [seen; 2]).collect();
            Ok(p.sky_pixels(values, mask))
        }),
    ),
    (
        "sky.in_front",
        Rule::Compare(|p, _| {
            let (projection, _) = p.sky()?;
            let values = projection.depth.iter().map(|&z| f32::from(u8::from(z > 0.0))).collect();
            Ok(host(HostTensor::new(vec![projection.depth.len() / projection.points, projection.points], values)))
        }),
    ),
    (
        "sky.proj_depth",
        Rule::Compare(|p, _| {
            let (projection, _) = p.sky()?;
            let values = projection.depth.iter().map(|&z| z as f32).collect();
            Ok(host(HostTensor::new(vec![projection.depth.len() / projection.points, projection.points], values)))
        }),
    ),
    (
        "sky.view_mask",
        Rule::Compare(|p, _| {
            let (projection, _) = p.sky()?;
            let (n, views) = (projection.points, projection.seen.len() / projection.points);
            let values = (0..n * views).map(|i| f32::from(u8::from(projection.seen[(i % views) * n + i / views])));
            Ok(host(HostTensor::new(vec![n, views], values.collect())))
        }),
    ),
    (
        "sky.proj_mask",
        Rule::Compare(|p, _| {
            let (projection, gaussians) = p.sky()?;
            let mut values = vec![0.0; projection.points];
            gaussians.visible_index.iter().for_each(|&i| values[i] = 1.0);
            Ok(host(HostTensor::new(vec![projection.points], values)))
        }),
    ),
    (
        "sky.visible_index",
        Rule::Compare(|p, _| {
            let index = &p.sky()?.1.visible_index;
            Ok(host(HostTensor::new(vec![index.len()], index.iter().map(|&i| i as f32).collect())))
        }),
    ),
    ("sky.rgb_mean", Rule::Compare(|p, _| Ok(dense(p.sky()?.1.rgb_mean.clone())))),
    ("sky.bg_field_out", Rule::Compare(|p, _| Ok(dense(p.sky()?.1.field_out.clone())))),
    ("sky.colors", Rule::Compare(|p, _| Ok(dense(p.sky()?.1.colors.clone())))),
    ("sky.means", Rule::Compare(|p, _| Ok(dense(p.sky()?.1.means.clone())))),
    ("sky.scales", Rule::Compare(|p, _| Ok(dense(p.sky()?.1.scales.clone())))),
    ("sky.quats", Rule::Compare(|p, _| Ok(dense(p.sky()?.1.quats.clone())))),
    ("sky.opacities", Rule::Compare(|p, _| Ok(dense(p.sky()?.1.opacities.clone())))),
    // Frame times, the static/dynamic opacity split and the lifespan decay.
    (
        "timestamps",
        Rule::Compare(|p, _| {
            let times: Vec<f32> = frame_times(p.images.dims()[1]).iter().map(|&t| t as f32).collect();
            Ok(host(HostTensor::new(vec![times.len()], times)))
        }),
    ),
    ("lifespan.static_opacity", Rule::Compare(|p, _| Ok(dense(p.frames(p.split_opacity(static_opacity)?))))),
    ("lifespan.dynamic_opacity", Rule::Compare(|p, _| Ok(dense(p.frames(p.split_opacity(dynamic_opacity)?))))),
    ("lifespan.static_opacity_at_t", Rule::Compare(|p, _| Ok(dense(p.static_opacity_at_t()?)))),
    (
        "lifespan.frame0_at_t2",
        Rule::Compare(|p, _| {
            let at_t = p.static_opacity_at_t()?;
            let [_, _, height, width] = at_t.dims();
            Ok(dense(at_t.narrow(0, 2, 1).narrow(1, 0, 1).reshape([height, width])))
        }),
    ),
    (
        "lifespan.frame0_raw_opacity_at_t2",
        Rule::Compare(|p, _| {
            let maps = &p.gaussians()?.maps;
            let [_, frames, height, width] = maps.opacity.dims();
            let time = *frame_times(frames).get(2).ok_or("the vectors have fewer than 3 frames")?;
            let first = |t: &Tensor<4>| t.clone().narrow(1, 0, 1).reshape([height, width]);
            let zero = Tensor::zeros([height, width], &maps.opacity.device());
            Ok(dense(opacity_at(first(&maps.opacity), first(&maps.lifespan), zero, time)))
        }),
    ),
    // The inference render.
    (
        "render.bg_mask",
        Rule::Compare(|p, _| {
            let values = p.non_sky()?.iter().map(|&b| f32::from(u8::from(b))).collect();
            Ok(host(HostTensor::new(p.per_frame(&[p.size.height as usize, p.size.width as usize]), values)))
        }),
    ),
    (
        "render.static_mask",
        Rule::Compare(|p, _| {
            let values = p.scene()?.static_mask.iter().map(|&b| f32::from(u8::from(b))).collect();
            Ok(host(HostTensor::new(p.per_frame(&[p.size.height as usize, p.size.width as usize]), values)))
        }),
    ),
    ("render.static_opacity", Rule::Compare(|p, _| Ok(dense(p.scene()?.static_opacity.clone())))),
    (
        "render.static_opacity_at_frame.{i}",
        Rule::Compare(|p, k| Ok(dense(layer(&p.scene()?.static_opacity_at_frame, k.index)?))),
    ),
    ("render.fg_rgb", Rule::Compare(|p, _| Ok(image(p.scene()?.foreground.colors.clone(), 3)))),
    ("render.fg_alpha", Rule::Compare(|p, _| Ok(image(p.scene()?.foreground.alpha.clone().unsqueeze_dim::<4>(3), 1)))),
    ("render.fg_expected_depth", Rule::Compare(|p, _| Ok(image(p.scene()?.foreground.depth.clone(), 1)))),
    ("render.sky_raw", Rule::Compare(|p, _| Ok(image(p.scene()?.sky.clone(), 3)))),
    ("render.sky_minmax", Rule::Compare(|p, _| Ok(image(p.scene()?.sky_minmax.clone(), 3)))),
    ("render.final_rgb", Rule::Compare(|p, _| Ok(image(p.scene()?.final_rgb.clone(), 3)))),
];

/// The rule for a reference output name and what its pattern matched.
fn lookup(name: &str) -> Option<(Rule, Key<'_>)> {
    OUTPUTS.iter().find_map(|(pattern, rule)| {
        let mut key = Key { index: 0, head: "" };
        let mut segments = name.split('.');
        for expected in pattern.split('.') {
            if expected == "{rest}" {
                return segments.next().map(|_| (*rule, key));
            }
            let segment = segments.next()?;
            match expected {
                "{i}" => key.index = segment.parse().ok()?,
                "{head}" if DPT_HEADS.contains(&segment) => key.head = segment,
                "{head}" => return None,
                literal if literal != segment => return None,
                _ => {}
            }
        }
        segments.next().is_none().then_some((*rule, key))
    })
}

fn layer<T: Clone>(list: &[T], index: usize) -> Result<T, String> {
    list.get(index).cloned().ok_or_else(|| format!("the port has {} entries, not {}", list.len(), index + 1))
}

/// One forward pass and what is derived from it on demand.
struct Prediction<'a> {
    model: &'a Dggt,
    images: Tensor<5>,
    out: DggtOutput,
    size: ImageSize,
    cameras: OnceCell<Result<Vec<(CameraFromWorld, PinholeIntrinsics)>, String>>,
    sky: OnceCell<Result<(SkyProjection, SkyGaussians), String>>,
    /// The vectors' `sky_mask` input, `[B, S, 3, H, W]` (1 = sky).
    sky_mask: Option<HostTensor>,
    scene: OnceCell<Result<SceneRender, String>>,
}

impl<'a> Prediction<'a> {
    fn new(model: &'a Dggt, images: Tensor<5>, out: DggtOutput) -> Self {
        let [.., height, width] = images.dims();
        let size = ImageSize::new(width as u32, height as u32).expect("the forward pass accepted the images");
        Self {
            model,
            images,
            out,
            size,
            cameras: OnceCell::new(),
            sky: OnceCell::new(),
            sky_mask: None,
            scene: OnceCell::new(),
        }
    }

    /// Compares the port's value of output `name` with `reference`.
    fn compare(&self, name: &str, reference: &HostTensor) -> ParityRow {
        let fail = |note: String| ParityRow::without_values(name, reference, Status::Fail, Some(note));
        let extract = match lookup(name) {
            None => {
                let reason = "not an output this port knows".to_string();
                return ParityRow::without_values(name, reference, Status::Skipped(reason), None);
            }
            Some((Rule::Compare(extract), key)) => extract(self, &key),
        };
        let actual = match extract {
            Ok(actual) => actual,
            Err(reason) => return fail(reason),
        };
        if actual.tensor.shape != reference.shape {
            return fail(format!("the port's shape is {:?}", actual.tensor.shape));
        }
        let map = actual.map.unwrap_or(|v| v);
        let compared = |i: usize| actual.mask.as_ref().is_none_or(|mask| mask[i]);
        let (mut max_ref, mut max_abs, mut finite) = (0.0f32, 0.0f32, true);
        let pairs = actual.tensor.values.iter().zip(&reference.values).enumerate();
        for (_, (&a, &r)) in pairs.filter(|(i, _)| compared(*i)) {
            let (a, r) = (map(a), map(r));
            finite &= a.is_finite() || a == r;
            max_ref = max_ref.max(r.abs());
            let difference = if a == r { 0.0 } else { (a - r).abs() };
            max_abs = if difference.is_nan() { f32::INFINITY } else { max_abs.max(difference) };
        }
        let tolerance = TOLERANCE.max(TOLERANCE * max_ref);
        let mut note = actual.note.map(str::to_string);
        let pass = match actual.pixel_channels {
            None => finite && max_abs <= tolerance,
            Some(channels) => {
                let within =
                    |(a, r): (&[f32], &[f32])| a.iter().zip(r).all(|(a, r)| a == r || (a - r).abs() <= tolerance);
                let pixels = actual.tensor.values.chunks(channels).zip(reference.values.chunks(channels));
                let total = actual.tensor.values.len() / channels;
                let good = pixels.filter(|&pair| within(pair)).count();
                let fraction = good as f64 / total.max(1) as f64;
                note = Some(if good == total {
                    format!("all {total} pixels within tolerance")
                } else {
                    format!(
                        "{good} of {total} pixels ({:.3}%) within tolerance; the others may legitimately differ: a \
                         transmittance crossing 1e-4 or an alpha crossing 1/255 on one side only",
                        100.0 * fraction
                    )
                });
                finite && fraction >= RENDER_PIXEL_FRACTION
            }
        };
        ParityRow {
            name: name.to_string(),
            shape: reference.shape.clone(),
            max_abs: Some(max_abs),
            max_rel: Some(max_abs / max_ref.max(f32::MIN_POSITIVE)),
            tolerance: Some(tolerance),
            status: if pass { Status::Pass } else { Status::Fail },
            note: if finite { note } else { Some("the port's values are not finite".into()) },
        }
    }

    /// `[B, S, ..rest]`.
    fn per_frame(&self, rest: &[usize]) -> Vec<usize> {
        let [batch, frames, ..] = self.images.dims();
        [batch, frames].iter().chain(rest).copied().collect()
    }

    fn dpt(&self, head: &str) -> Result<&DptOutput, String> {
        match head {
            "depth_head" => Ok(&self.out.depth.dpt),
            "point_head" => Ok(&self.points()?.dpt),
            "gs_head" => Ok(&self.gaussians()?.dpt),
            "instance_head" => Ok(&self.instance()?.dpt),
            "semantic_head" => Ok(&self.semantic()?.dpt),
            other => Err(format!("no DPT head {other}")),
        }
    }

    fn gaussians(&self) -> Result<&GaussianOutput, String> {
        self.out.gaussians.as_ref().ok_or_else(|| "the network has no gs_head".into())
    }

    fn instance(&self) -> Result<&DptPrediction, String> {
        self.out.instance.as_ref().ok_or_else(|| "the network has no instance_head".into())
    }

    fn points(&self) -> Result<&DptPrediction, String> {
        self.out.points.as_ref().ok_or_else(|| "the forward pass did not run the point_head".into())
    }

    fn semantic(&self) -> Result<&DptPrediction, String> {
        self.out.semantic.as_ref().ok_or_else(|| "the network has no semantic_head".into())
    }

    /// The dynamic logit, channel 0 of the instance prediction, `[B, S, H, W]`.
    fn dynamic_logit(&self) -> Result<Tensor<4>, String> {
        Ok(self.instance()?.prediction.clone().narrow(4, 0, 1).squeeze_dim::<4>(4))
    }

    /// The camera of every frame (batch-major), decoded from the pose encoding.
    fn cameras(&self) -> Result<&[(CameraFromWorld, PinholeIntrinsics)], String> {
        let decoded = self.cameras.get_or_init(|| {
            let encodings = HostTensor::from_tensor(self.out.camera.pose_encoding()).values;
            encodings
                .chunks(9)
                .map(|frame| {
                    let values: [f64; 9] = std::array::from_fn(|i| frame[i] as f64);
                    PoseEncoding::from_array(values).decode(self.size).map_err(|e| format!("decoding the pose: {e}"))
                })
                .collect()
        });
        decoded.as_deref().map_err(Clone::clone)
    }

    /// The depth of every frame unprojected at integer pixel coordinates (as the release does), in world or
    /// camera space, `[B, S, H, W, 3]`.
    fn means(&self, world: bool) -> Result<Actual, String> {
        let depth = HostTensor::from_tensor(self.out.depth.prediction.clone()).values;
        let mut values = Vec::with_capacity(depth.len() * 3);
        let width = self.size.width as usize;
        for ((camera_from_world, k), depth) in self.cameras()?.iter().zip(depth.chunks(self.size.area())) {
            if world {
                let convention = PixelConvention::Integer;
                let points = unproject_depth_map(depth, self.size, k, camera_from_world, convention)
                    .map_err(|e| format!("unprojecting the depth: {e}"))?;
                values.extend(points.iter().flat_map(|p| p.to_array()).map(|v| v as f32));
            } else {
                values.extend(depth.iter().enumerate().flat_map(|(i, &d)| {
                    let pixel = PixelConvention::Integer.coordinates((i % width) as u32, (i / width) as u32);
                    k.unproject(pixel, d as f64).to_array().map(|v| v as f32)
                }));
            }
        }
        let shape = self.per_frame(&[self.size.height as usize, width, 3]);
        Ok(host(HostTensor::new(shape, values)))
    }

    /// The sky points projected with the predicted cameras and coloured from the input images.
    fn sky(&self) -> Result<&(SkyProjection, SkyGaussians), String> {
        let sky = self.sky.get_or_init(|| {
            let model = self.model.sky_model.as_ref().ok_or("the network has no sky_model")?;
            let [batch, frames, channels, height, width] = self.images.dims();
            if batch != 1 {
                return Err(format!("the sky model colours one scene; the vectors hold {batch}"));
            }
            let cameras = self.cameras()?;
            let images = self.images.clone().reshape([frames, channels, height, width]);
            Ok((model.project(cameras, self.size), model.gaussians(images, cameras)))
        });
        sky.as_ref().map_err(Clone::clone)
    }

    /// `[1, S, ..]` to `[S, ..]`.
    fn frames(&self, tensor: Tensor<4>) -> Tensor<3> {
        tensor.squeeze_dim::<3>(0)
    }

    /// The Gaussian opacity split by the dynamic logit with `split`, `[B, S, H, W]`.
    fn split_opacity(&self, split: fn(Tensor<4>, Tensor<4>) -> Tensor<4>) -> Result<Tensor<4>, String> {
        Ok(split(self.gaussians()?.maps.opacity.clone(), self.dynamic_logit()?))
    }

    /// Every frame's static opacity seen at every frame's time, `[render frame, source frame, H, W]`.
    fn static_opacity_at_t(&self) -> Result<Tensor<4>, String> {
        let alpha = self.frames(self.split_opacity(static_opacity)?);
        let lifespan = self.frames(self.gaussians()?.maps.lifespan.clone());
        let [frames, height, width] = alpha.dims();
        let times = frame_times(frames);
        let source: Vec<f32> = times.iter().flat_map(|&t| std::iter::repeat_n(t as f32, height * width)).collect();
        let source = Tensor::<3>::from_data(TensorData::new(source, [frames, height, width]), &alpha.device());
        let at = |&t: &f64| opacity_at(alpha.clone(), lifespan.clone(), source.clone(), t);
        Ok(Tensor::stack(times.iter().map(at).collect(), 0))
    }

    /// Per pixel of every frame, row-major: not sky in the vectors' `sky_mask` (any channel 0).
    fn non_sky(&self) -> Result<Vec<bool>, String> {
        let mask = self.sky_mask.as_ref().ok_or("inputs.safetensors has no `sky_mask`")?;
        let pixels = self.size.area();
        if mask.values.len() != self.images.dims()[..2].iter().product::<usize>() * 3 * pixels {
            return Err(format!("`sky_mask` is {:?}, not [B, S, 3, H, W]", mask.shape));
        }
        Ok(mask
            .values
            .chunks(3 * pixels)
            .flat_map(|frame| (0..pixels).map(move |i| (0..3).any(|c| frame[c * pixels + i] == 0.0)))
            .collect())
    }

    /// The release's inference render of the scene.
    fn scene(&self) -> Result<&SceneRender, String> {
        let scene = self.scene.get_or_init(|| {
            let means = self.means(true)?.tensor.to_tensor::<5>(&self.images.device()).ok_or("means are not 5D")?;
            let non_sky = self.non_sky()?;
            let inputs = SceneInputs {
                maps: &self.gaussians()?.maps,
                dynamic_logit: self.dynamic_logit()?,
                means,
                non_sky: &non_sky,
                cameras: self.cameras()?,
                sky: &self.sky()?.1,
            };
            render_scene(&inputs, self.size)
        });
        scene.as_ref().map_err(Clone::clone)
    }

    /// Sky pixel coordinates `[S, N, 2]`, compared where `mask` holds: behind a camera the release's values are
    /// clamped garbage, and in front of it but far outside the image (grazing depths) `x / z` amplifies the
    /// reference's `f32` rounding beyond any fixed relative tolerance. Whether points are in front and seen is
    /// compared exactly by `sky.in_front` and `sky.view_mask`.
    fn sky_pixels(&self, values: Vec<f32>, mask: Vec<bool>) -> Actual {
        let points = values.len() / 2;
        let views = self.images.dims()[1];
        let mut actual = host(HostTensor::new(vec![views, points / views, 2], values));
        actual.mask = Some(mask);
        actual.note = Some("compared where the point is seen: in front of the camera, inside the image");
        actual
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_resolve_through_the_table() {
        fn matches(name: &str) -> Option<(bool, usize, &str)> {
            lookup(name).map(|(rule, key)| (matches!(rule, Rule::Compare(_)), key.index, key.head))
        }
        assert_eq!(matches("agg.output_list.3"), Some((true, 3, "")));
        assert_eq!(matches("dbg.gs_head.resize.2"), Some((true, 2, "gs_head")));
        assert_eq!(matches("instance_head.raw"), Some((true, 0, "instance_head")));
        assert_eq!(matches("render.static_opacity_at_frame.1"), Some((true, 1, "")));
        assert_eq!(matches("lifespan.frame0_at_t2"), Some((true, 0, "")));
        assert!(matches("render").is_none());
        assert!(matches("agg.output_list.x").is_none());
        assert!(matches("agg.output_list.1.2").is_none());
        assert!(matches("track_head.raw").is_none());
        assert!(matches("something_new").is_none());
    }

    #[test]
    fn table_lists_rows_and_skip_reasons() {
        let reference = HostTensor::new(vec![2], vec![1.0, 2.0]);
        let report = ParityReport {
            weights: PathBuf::from("w.safetensors"),
            load: LoadReport::default(),
            rows: vec![
                ParityRow {
                    name: "depth".into(),
                    shape: vec![2],
                    max_abs: Some(2e-5),
                    max_rel: Some(1e-5),
                    tolerance: Some(2e-4),
                    status: Status::Pass,
                    note: None,
                },
                ParityRow::without_values("track.coords", &reference, Status::Skipped("unknown".into()), None),
            ],
        };
        let table = report.to_string();
        assert!(table.lines().nth(1).unwrap().starts_with("depth") && table.contains("2.000e-5"), "{table}");
        assert!(table.contains("track.coords") && table.contains("not compared (unknown)"), "{table}");
        assert!(report.passed());
        assert_eq!(report.summary(), "2 outputs: 1 pass, 0 fail, 1 not compared");
    }
}
