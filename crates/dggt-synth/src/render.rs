//! Rendering one view (frame, camera) by casting rays through the pixels.
//!
//! Pixel `(col, row)` covers `[col, col + 1] x [row, row + 1]` of the image `[0, W] x [0, H]`
//! ([`PixelConvention::Centred`]); the ray through continuous coordinates `(u, v)` has the OpenCV camera-frame
//! direction `((u - cx) / fx, (v - cy) / fy, 1)`.
//!
//! - Colour: the mean of 2x2 rays at `(col + 0.25 | 0.75, row + 0.25 | 0.75)`.
//! - Masks: one ray through the pixel centre. Sky: it hits nothing. Dynamic: it hits a car moving faster than
//!   1 m/s. Dynamic box: it crosses the 3D box of such a car, whatever is in front (the projected-box mask).
//! - Depth and flow at quarter resolution: one ray through `(4 col + 2, 4 row + 2)` of the full-resolution image;
//!   z-depth in metres along the camera's optical axis (0 for sky) and the world-frame velocity (m/s) of the
//!   surface point (zero for static surfaces and sky).
//!
//! Rows are rendered in parallel; every pixel is computed on its own, so the result does not depend on
//! scheduling.

use std::collections::BTreeSet;

use dggt_geom::glam::{DMat3, DVec3};
use dggt_geom::{PixelConvention, WorldFromCamera};
use image::{GrayImage, Rgb, RgbImage};
use rayon::prelude::*;

use crate::config::SynthConfig;
use crate::error::{Result, SynthError};
use crate::object_id::ObjectId;
use crate::scene::{SceneAt, SynthScene};
use crate::shapes::Aabb;

/// Channels of a depth-flow sample: z-depth, then world velocity x, y, z.
pub const DEPTH_FLOW_CHANNELS: usize = 4;
/// Downsampling factor of the depth-flow maps.
pub const DEPTH_FLOW_STRIDE: u32 = 4;

/// Everything rendered for one view.
#[derive(Debug, Clone)]
pub struct RenderedView {
    pub frame: usize,
    pub camera: usize,
    pub image: RgbImage,
    /// 255 where the centre ray hits nothing.
    pub sky_mask: GrayImage,
    /// 255 where the centre ray hits a moving car (exact, occlusion-aware).
    pub dynamic_mask: GrayImage,
    /// 255 where the centre ray crosses a moving car's 3D box (ignores occlusion).
    pub dynamic_box_mask: GrayImage,
    /// Row-major `(H/4, W/4, 4)` float32: z-depth then world velocity.
    pub depth_flow: Vec<f32>,
    /// `[H/4, W/4, 4]`.
    pub depth_flow_shape: [usize; 3],
    /// Cars (instance ids) hit by at least one pixel-centre ray, and moving cars whose box one crosses.
    pub visible_instances: BTreeSet<ObjectId>,
}

/// The half-spaces bounding what a camera can see; used to skip objects outside the view.
struct Frustum {
    apex: DVec3,
    inward_normals: [DVec3; 5],
}

impl Frustum {
    fn new(pose: &WorldFromCamera, corner_directions: [DVec3; 4]) -> Self {
        let forward = pose.transform_vector(DVec3::Z);
        let d = corner_directions.map(|c| pose.transform_vector(c));
        let side = |a: DVec3, b: DVec3| {
            let n = a.cross(b);
            if n.dot(forward) < 0.0 { -n } else { n }
        };
        Self {
            apex: pose.translation(),
            inward_normals: [forward, side(d[0], d[1]), side(d[1], d[2]), side(d[2], d[3]), side(d[3], d[0])],
        }
    }

    /// False only when the box lies entirely outside one of the bounding planes.
    fn may_contain(&self, b: &Aabb) -> bool {
        let corners = b.corners();
        self.inward_normals.iter().all(|n| corners.iter().any(|&c| (c - self.apex).dot(*n) >= 0.0))
    }
}

/// Per-pixel results of one image row.
struct RowPixels {
    colour: Vec<[u8; 3]>,
    sky: Vec<bool>,
    dynamic: Vec<bool>,
    dynamic_box: Vec<bool>,
    visible: BTreeSet<ObjectId>,
}

fn to_byte(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

fn mask(width: u32, height: u32, rows: &[RowPixels], pick: impl Fn(&RowPixels) -> &Vec<bool>) -> GrayImage {
    let data: Vec<u8> = rows.iter().flat_map(|r| pick(r).iter().map(|&on| if on { 255 } else { 0 })).collect();
    GrayImage::from_raw(width, height, data).expect("one value per pixel")
}

impl SynthScene {
    /// Renders `frame` from `camera`.
    pub fn render_view(&self, frame: usize, camera: usize) -> Result<RenderedView> {
        let pose = self.world_from_camera(frame, camera).ok_or(SynthError::NoSuchView {
            frame,
            camera,
            frames: self.config.frames,
            cameras: self.config.cameras,
        })?;
        let (width, height) = (self.size.width, self.size.height);
        let k = self.intrinsics;
        let camera_direction = |u: f64, v: f64| DVec3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
        let (w, h) = (width as f64, height as f64);
        let frustum = Frustum::new(
            &pose,
            [camera_direction(0.0, 0.0), camera_direction(w, 0.0), camera_direction(w, h), camera_direction(0.0, h)],
        );
        let time = SynthConfig::frame_time(frame);
        let scene = SceneAt::new(self, time, |b| frustum.may_contain(b));
        let rotation: DMat3 = pose.rotation_matrix();
        let origin = pose.translation();
        // World ray through continuous image coordinates: (unit direction, length of the camera-frame direction).
        let ray = |u: f64, v: f64| {
            let d = rotation * camera_direction(u, v);
            let length = d.length();
            (d / length, length)
        };
        let colour_at = |u: f64, v: f64| {
            let (dir, _) = ray(u, v);
            match scene.trace(origin, dir) {
                Some(trace) => scene.colour(&trace, origin, dir),
                None => scene.sky(dir),
            }
        };

        let rows: Vec<RowPixels> = (0..height)
            .into_par_iter()
            .map(|row| {
                let mut out = RowPixels {
                    colour: Vec::with_capacity(width as usize),
                    sky: Vec::with_capacity(width as usize),
                    dynamic: Vec::with_capacity(width as usize),
                    dynamic_box: Vec::with_capacity(width as usize),
                    visible: BTreeSet::new(),
                };
                for col in 0..width {
                    let centre = PixelConvention::Centred.coordinates(col, row);
                    let (dir, _) = ray(centre.x, centre.y);
                    let hit = scene.trace(origin, dir);
                    out.sky.push(hit.is_none());
                    out.dynamic.push(hit.as_ref().is_some_and(|t| scene.is_dynamic(t)));
                    let mut crossed = false;
                    for id in scene.moving_boxes_crossed(origin, dir) {
                        crossed = true;
                        out.visible.insert(id);
                    }
                    out.dynamic_box.push(crossed);
                    if let Some(object) = hit.as_ref().map(|t| scene.object(t)).filter(|o| o.kind().is_vehicle()) {
                        out.visible.insert(object.id());
                    }
                    let mut sum = DVec3::ZERO;
                    for (du, dv) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                        sum += colour_at(col as f64 + du, row as f64 + dv);
                    }
                    let mean = sum / 4.0;
                    out.colour.push([to_byte(mean.x), to_byte(mean.y), to_byte(mean.z)]);
                }
                out
            })
            .collect();

        let mut image = RgbImage::new(width, height);
        for (row, pixels) in rows.iter().enumerate() {
            for (col, rgb) in pixels.colour.iter().enumerate() {
                image.put_pixel(col as u32, row as u32, Rgb(*rgb));
            }
        }
        let visible_instances = rows.iter().flat_map(|r| r.visible.iter().copied()).collect();

        let (low_w, low_h) = (width / DEPTH_FLOW_STRIDE, height / DEPTH_FLOW_STRIDE);
        let stride = DEPTH_FLOW_STRIDE as f64;
        let depth_flow: Vec<f32> = (0..low_h)
            .into_par_iter()
            .flat_map_iter(|row| {
                let scene = &scene;
                (0..low_w).flat_map(move |col| {
                    let (u, v) = (stride * col as f64 + stride / 2.0, stride * row as f64 + stride / 2.0);
                    let (dir, length) = ray(u, v);
                    match scene.trace(origin, dir) {
                        None => [0.0; DEPTH_FLOW_CHANNELS],
                        Some(trace) => {
                            let velocity = scene.velocity(&trace, origin + dir * trace.t);
                            [(trace.t / length) as f32, velocity.x as f32, velocity.y as f32, velocity.z as f32]
                        }
                    }
                })
            })
            .collect();

        Ok(RenderedView {
            frame,
            camera,
            image,
            sky_mask: mask(width, height, &rows, |r| &r.sky),
            dynamic_mask: mask(width, height, &rows, |r| &r.dynamic),
            dynamic_box_mask: mask(width, height, &rows, |r| &r.dynamic_box),
            depth_flow,
            depth_flow_shape: [low_h as usize, low_w as usize, DEPTH_FLOW_CHANNELS],
            visible_instances,
        })
    }
}
