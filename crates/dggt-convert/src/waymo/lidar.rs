//! Waymo range images (zlib-compressed `MatrixFloat`s) turned into the export's lidar rows
//! (`lidar/{t}.bin`, N x 14 float32: origin xyz, point xyz, flow xyz, flow class, ground, intensity, elongation,
//! laser id), in the vehicle frame of `Frame.pose`.
//!
//! Per laser, first return only (the export's choice), for every pixel with range > 0:
//! - row `i` of an `H`-row image has inclination `incl[H - 1 - i]` (the stored list is lowest beam first; when it
//!   is empty the beams are spread uniformly, `min + (j + 0.5) / H · (max - min)`);
//! - column `c` of `W` has azimuth `((W - c - 0.5) / W · 2 - 1) · π - atan2(L[1][0], L[0][0])`, `L` the
//!   lidar -> vehicle extrinsic;
//! - the point is `L · r (cos az cos incl, sin az cos incl, sin incl)`, the ray origin `L · 0`;
//! - the TOP lidar's per-pixel pose (vehicle -> global at the pixel's time; roll, pitch, yaw with
//!   `R = Rz(yaw) Ry(pitch) Rx(roll)`) moves both into the frame pose's vehicle frame:
//!   `inv(Frame.pose) · P_pixel · p`.
//!
//! Flow (m/s, and its class: -1 none, 0 background, 1 vehicle, 2 pedestrian, 3 sign, 4 cyclist) comes from the
//! scene-flow release's flow image; without one, flow is zero and the class -1. The laser id is
//! `LaserName - 1` (0 = TOP). The ground flag comes from [`ground`](super::ground).

use std::f64::consts::PI;
use std::io::Read;

use dggt_geom::glam::{DMat3, DMat4, DVec3};
use flate2::read::ZlibDecoder;
use prost::Message;

use super::frame::{Rows4, rigid_rows};
use super::proto;
use crate::error::{RecordAt, Result};

/// Floats per exported lidar row.
pub const ROW_LEN: usize = 14;
/// One exported lidar row.
pub type LidarRow = [f32; ROW_LEN];
/// Column of the ground flag in a [`LidarRow`].
pub const GROUND_COLUMN: usize = 10;
const TOP: i32 = 1;

/// One lidar's calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct LaserCalibration {
    /// `LaserName`: TOP 1, FRONT 2, SIDE_LEFT 3, SIDE_RIGHT 4, REAR 5.
    pub name: i32,
    /// Beam inclinations (radians), lowest first; empty when uniform.
    pub inclinations: Vec<f64>,
    pub inclination_range: Option<(f64, f64)>,
    /// Lidar -> vehicle.
    pub vehicle_from_lidar: DMat4,
}

/// The context's lidar calibrations.
pub fn laser_calibrations(at: RecordAt, context: &proto::Context) -> Result<Vec<LaserCalibration>> {
    context
        .laser_calibrations
        .iter()
        .map(|calibration| {
            let name = match calibration.name {
                Some(name @ 1..=5) => name,
                other => return Err(at.content("a laser calibration with a laser name 1..=5", format!("{other:?}"))),
            };
            let what = format!("extrinsic of laser {name}");
            let (rows, _) = rigid_rows::<dggt_geom::Ego, dggt_geom::Sweep>(at, &what, calibration.extrinsic.as_ref())?;
            Ok(LaserCalibration {
                name,
                inclinations: calibration.beam_inclinations.clone(),
                inclination_range: calibration.beam_inclination_min.zip(calibration.beam_inclination_max),
                vehicle_from_lidar: matrix(&rows),
            })
        })
        .collect()
}

/// The homogeneous matrix of row-major rows.
pub fn matrix(rows: &Rows4) -> DMat4 {
    DMat4::from_cols_array_2d(rows).transpose()
}

/// The rows of every first return of every laser that has a range image, or `None` when none has.
pub fn frame_points(
    at: RecordAt,
    frame: &proto::Frame,
    lasers: &[LaserCalibration],
    global_from_vehicle: &DMat4,
) -> Result<Option<Vec<LidarRow>>> {
    let vehicle_from_global = global_from_vehicle.inverse();
    let mut rows = Vec::new();
    let mut any = false;
    for laser in &frame.lasers {
        let Some(range_image) = laser.ri_return1.as_ref().filter(|r| r.range_image_compressed.is_some()) else {
            continue;
        };
        any = true;
        let calibration = lasers.iter().find(|c| Some(c.name) == laser.name).ok_or_else(|| {
            at.content("a calibration for every laser with a range image", format!("none for laser {:?}", laser.name))
        })?;
        laser_points(at, calibration, range_image, &vehicle_from_global, &mut rows)?;
    }
    Ok(any.then_some(rows))
}

/// A decompressed `[H, W, C]` float image with at least `channels` channels.
struct Image {
    height: usize,
    width: usize,
    channels: usize,
    data: Vec<f32>,
}

impl Image {
    fn at(&self, row: usize, col: usize) -> &[f32] {
        let start = (row * self.width + col) * self.channels;
        &self.data[start..start + self.channels]
    }
}

fn decode_image(at: RecordAt, what: &str, compressed: &[u8], channels: usize) -> Result<Image> {
    let mut bytes = Vec::new();
    ZlibDecoder::new(compressed)
        .read_to_end(&mut bytes)
        .map_err(|e| at.content(format!("{what}: zlib-compressed data"), e.to_string()))?;
    let matrix = proto::MatrixFloat::decode(bytes.as_slice())
        .map_err(|e| at.content(format!("{what}: a MatrixFloat"), e.to_string()))?;
    let dims = matrix.shape.map(|s| s.dims).unwrap_or_default();
    let [height, width, found_channels] = dims.as_slice() else {
        return Err(at.content(format!("{what}: shape [H, W, C]"), format!("{dims:?}")));
    };
    let [height, width, found_channels] = [*height, *width, *found_channels].map(|d| d.max(0) as usize);
    if found_channels < channels || height * width * found_channels != matrix.data.len() {
        return Err(at.content(
            format!("{what}: at least {channels} channels and H·W·C values"),
            format!("shape {dims:?} with {} values", matrix.data.len()),
        ));
    }
    Ok(Image { height, width, channels: found_channels, data: matrix.data })
}

fn laser_points(
    at: RecordAt,
    calibration: &LaserCalibration,
    range_image: &proto::RangeImage,
    vehicle_from_global: &DMat4,
    rows: &mut Vec<LidarRow>,
) -> Result<()> {
    let what = |field: &str| format!("laser {} {field}", calibration.name);
    let compressed = range_image.range_image_compressed.as_deref().unwrap_or_default();
    let ranges = decode_image(at, &what("range image"), compressed, 4)?;
    let (height, width) = (ranges.height, ranges.width);
    let same_size = |image: Image, field: &str| {
        if (image.height, image.width) == (height, width) {
            Ok(image)
        } else {
            Err(at.content(
                format!("{} of {height} x {width}", what(field)),
                format!("{} x {}", image.height, image.width),
            ))
        }
    };
    let flow = match range_image.range_image_flow_compressed.as_deref() {
        Some(bytes) => Some(same_size(decode_image(at, &what("flow image"), bytes, 4)?, "flow image")?),
        None => None,
    };
    let poses = match range_image.range_image_pose_compressed.as_deref() {
        Some(bytes) if calibration.name == TOP => {
            Some(same_size(decode_image(at, &what("pose image"), bytes, 6)?, "pose image")?)
        }
        _ => None,
    };
    let inclinations = row_inclinations(at, calibration, height)?;
    let l = calibration.vehicle_from_lidar;
    let azimuth_offset = l.x_axis.y.atan2(l.x_axis.x);
    let origin = l.transform_point3(DVec3::ZERO);
    let laser_id = (calibration.name - 1) as f32;
    for (row, inclination) in inclinations.iter().enumerate() {
        let (sin_incl, cos_incl) = inclination.sin_cos();
        for col in 0..width {
            let pixel = ranges.at(row, col);
            let range = pixel[0] as f64;
            if range <= 0.0 {
                continue;
            }
            let azimuth = ((width - col) as f64 - 0.5) / width as f64 * 2.0 * PI - PI - azimuth_offset;
            let (sin_az, cos_az) = azimuth.sin_cos();
            let in_lidar = DVec3::new(cos_az * cos_incl, sin_az * cos_incl, sin_incl) * range;
            let (mut point, mut ray_origin) = (l.transform_point3(in_lidar), origin);
            if let Some(poses) = &poses {
                let compensate = *vehicle_from_global * pixel_pose(poses.at(row, col));
                point = compensate.transform_point3(point);
                ray_origin = compensate.transform_point3(ray_origin);
            }
            let (velocity, class) = match &flow {
                Some(flow) => {
                    let f = flow.at(row, col);
                    ([f[0], f[1], f[2]], f[3])
                }
                None => ([0.0; 3], -1.0),
            };
            let (o, p) = (ray_origin.as_vec3(), point.as_vec3());
            rows.push([
                o.x,
                o.y,
                o.z,
                p.x,
                p.y,
                p.z,
                velocity[0],
                velocity[1],
                velocity[2],
                class,
                0.0,
                pixel[1],
                pixel[2],
                laser_id,
            ]);
        }
    }
    Ok(())
}

/// Inclination of each range-image row, highest beam (row 0) first.
fn row_inclinations(at: RecordAt, calibration: &LaserCalibration, height: usize) -> Result<Vec<f64>> {
    let mut lowest_first = if calibration.inclinations.is_empty() {
        let (min, max) = calibration.inclination_range.ok_or_else(|| {
            at.content(format!("laser {}: beam inclinations or their min and max", calibration.name), "neither")
        })?;
        (0..height).map(|j| min + (j as f64 + 0.5) / height as f64 * (max - min)).collect()
    } else {
        calibration.inclinations.clone()
    };
    if lowest_first.len() != height {
        return Err(at.content(
            format!("laser {}: one beam inclination per range-image row ({height})", calibration.name),
            format!("{}", lowest_first.len()),
        ));
    }
    lowest_first.reverse();
    Ok(lowest_first)
}

/// Vehicle -> global at one pixel's time, from `[roll, pitch, yaw, x, y, z]`.
fn pixel_pose(pose: &[f32]) -> DMat4 {
    let [roll, pitch, yaw, x, y, z] = [pose[0], pose[1], pose[2], pose[3], pose[4], pose[5]].map(f64::from);
    let rotation = DMat3::from_rotation_z(yaw) * DMat3::from_rotation_y(pitch) * DMat3::from_rotation_x(roll);
    DMat4::from_mat3_translation(rotation, DVec3::new(x, y, z))
}
