//! A readable summary of a scene: what `dggt inspect` prints, and a JSON-serialisable record of it.

use std::fmt;

use serde::Serialize;

use crate::depth_flow::FlowOrigin;
use crate::error::Result;
use crate::preprocess::Preprocess;
use crate::scene::Scene;

/// What a user wants to know about a log before training on it.
#[derive(Debug, Clone, Serialize)]
pub struct SceneSummary {
    pub name: String,
    pub root: String,
    pub source: String,
    pub frames: usize,
    pub first_frame: usize,
    pub last_frame: usize,
    pub duration_s: f64,
    pub cameras: Vec<CameraSummary>,
    pub sky_masks: bool,
    pub dynamic_masks: bool,
    pub fine_dynamic_masks: bool,
    pub depth_flows: bool,
    /// Where the `depth_flows_4` maps' scene flow comes from.
    pub scene_flow: FlowOrigin,
    pub lidar_sweeps: usize,
    /// Path length driven by the first camera, metres.
    pub trajectory_length_m: f64,
    /// Mean speed of the first camera, metres per second.
    pub mean_speed_m_s: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct CameraSummary {
    pub id: usize,
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub fov_h_deg: f64,
    pub fov_w_deg: f64,
    pub has_distortion: bool,
    /// Size after the release's preprocessing (width 518).
    pub network_width: u32,
    pub network_height: u32,
}

impl SceneSummary {
    /// The summary of `scene`; fails only on a conversion marker that cannot be read.
    pub fn of(scene: &Scene) -> Result<Self> {
        let preprocess = Preprocess::default();
        let cameras = scene
            .cameras
            .iter()
            .map(|c| {
                let (fov_h, fov_w) = c.intrinsics.fov(c.size);
                let network = preprocess.plan(c.size).map(|p| p.output).ok();
                CameraSummary {
                    id: c.id,
                    name: c.name.clone(),
                    width: c.size.width,
                    height: c.size.height,
                    fx: c.intrinsics.fx,
                    fy: c.intrinsics.fy,
                    cx: c.intrinsics.cx,
                    cy: c.intrinsics.cy,
                    fov_h_deg: fov_h.to_degrees(),
                    fov_w_deg: fov_w.to_degrees(),
                    has_distortion: c.distortion.iter().any(|&d| d != 0.0),
                    network_width: network.map_or(0, |s| s.width),
                    network_height: network.map_or(0, |s| s.height),
                }
            })
            .collect();
        let duration_s = scene.frames.last().map_or(0.0, |f| f.timestamp);
        let trajectory_length_m = if scene.cameras.is_empty() { 0.0 } else { scene.trajectory_length(0) };
        Ok(Self {
            name: scene.name.clone(),
            root: scene.root.display().to_string(),
            source: scene.source.describe(),
            frames: scene.frames.len(),
            first_frame: scene.frames.first().map_or(0, |f| f.index),
            last_frame: scene.frames.last().map_or(0, |f| f.index),
            duration_s,
            cameras,
            sky_masks: scene.all_views_have(|v| v.sky_mask.is_some()),
            dynamic_masks: scene.all_views_have(|v| v.dynamic_mask.is_some()),
            fine_dynamic_masks: scene.all_views_have(|v| v.fine_dynamic_mask.is_some()),
            depth_flows: scene.all_views_have(|v| v.depth_flow.is_some()),
            scene_flow: scene.flow_origin()?,
            lidar_sweeps: scene.lidar.iter().filter(|l| l.is_some()).count(),
            trajectory_length_m,
            mean_speed_m_s: if duration_s > 0.0 { trajectory_length_m / duration_s } else { 0.0 },
        })
    }
}

impl fmt::Display for SceneSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let yes_no = |b: bool| if b { "yes" } else { "no" };
        writeln!(f, "scene      {} ({})", self.name, self.source)?;
        writeln!(f, "path       {}", self.root)?;
        writeln!(
            f,
            "frames     {} (indices {}..={}, {:.1} s)",
            self.frames, self.first_frame, self.last_frame, self.duration_s
        )?;
        writeln!(
            f,
            "trajectory {:.2} m driven by camera {}, mean speed {:.2} m/s",
            self.trajectory_length_m,
            self.cameras.first().map_or("-", |c| c.name.as_str()),
            self.mean_speed_m_s
        )?;
        writeln!(f, "cameras    {}", self.cameras.len())?;
        writeln!(
            f,
            "  id  name               size        fx        fy        cx        cy    fov h x w (deg)  network"
        )?;
        for c in &self.cameras {
            writeln!(
                f,
                "  {:<3} {:<18} {:>4}x{:<5} {:>9.2} {:>9.2} {:>9.2} {:>9.2}  {:>6.1} x {:<6.1}  {}x{}{}",
                c.id,
                c.name,
                c.width,
                c.height,
                c.fx,
                c.fy,
                c.cx,
                c.cy,
                c.fov_h_deg,
                c.fov_w_deg,
                c.network_width,
                c.network_height,
                if c.has_distortion { "  (distortion ignored)" } else { "" }
            )?;
        }
        writeln!(
            f,
            "masks      sky: {}, dynamic: {}, fine dynamic: {}",
            yes_no(self.sky_masks),
            yes_no(self.dynamic_masks),
            yes_no(self.fine_dynamic_masks)
        )?;
        writeln!(f, "depth      depth_flows_4: {}, lidar sweeps: {}", yes_no(self.depth_flows), self.lidar_sweeps)?;
        write!(f, "flow       {}", self.scene_flow.describe())
    }
}
