//! The nuScenes converter on a real log: PandaSet sequence 002 in the nuScenes devkit layout (40 frames at 10 Hz,
//! six cameras, tracked boxes of moving and parked cars; `../shared/real-data/pandaset-002`, or
//! `$DGGT_REAL_DATA`; read in place, never copied).
//!
//! What is checked is what a user of the export sees at each box centre: the dataset's own motion labels
//! (`vehicle.moving` against `vehicle.parked` / `vehicle.stopped`) are the truth, the centre is placed at the
//! camera's own time (each camera fires 19-100 ms before the sample's lidar time) and projected through the
//! export's own cameras, and the export's dynamic mask is read there. A car partly outside the image counts as
//! long as its centre projects inside. A view whose centre is hidden behind another vehicle's box (the ray from
//! the camera to the centre passes through a nearer box) shows that other vehicle there, so it is counted apart:
//! a parked car behind a passing one is rightly dynamic at its centre.

use crate::common;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use dggt_convert::depth_flows::DepthFlows;
use dggt_convert::masks::DynamicMaskStyle;
use dggt_convert::nuscenes::{FrameRate, NuScenesOptions, NuScenesVersion, Tables, convert_scene};
use dggt_convert::sky::SkyMasks;
use dggt_data::{DynamicMaskKind, ExportLayout, images, text};
use dggt_geom::glam::{DMat4, DVec3};
use dggt_geom::ray_box_interval;
use serde_json::Value;

fn root() -> PathBuf {
    common::real_data().join("pandaset-002")
}

const VERSION: &str = "v1.0-pandaset";

fn table(name: &str) -> Vec<Value> {
    let path = root().join(VERSION).join(format!("{name}.json"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice::<Vec<Value>>(&bytes).unwrap()
}

fn by_token(rows: &[Value]) -> HashMap<String, &Value> {
    rows.iter().map(|row| (row["token"].as_str().unwrap().to_owned(), row)).collect()
}

/// Whether a vehicle moves, by the dataset's label.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Motion {
    Moving,
    /// Parked or stopped.
    Still,
}

/// One annotated vehicle at one sample: its track, label and centre (global frame).
struct Annotation {
    instance: String,
    sample: String,
    motion: Motion,
    centre: DVec3,
    /// Heading about the world's z axis (radians).
    yaw: f64,
    /// Length, width, height (m).
    size: DVec3,
}

impl Annotation {
    /// The distance along the unit ray from `origin` at which it enters this box when centred at `centre`, if it
    /// does (in the box's axes: x along the length).
    fn entry(&self, centre: DVec3, origin: DVec3, direction: DVec3) -> Option<f64> {
        let turn = dggt_geom::glam::DQuat::from_rotation_z(-self.yaw);
        let (entry, exit) = ray_box_interval(turn * (origin - centre), turn * direction, self.size * 0.5)?;
        (exit > 0.0).then_some(entry.max(0.0))
    }
}

/// The log's vehicle annotations, with the dataset's motion labels.
fn vehicle_annotations() -> Vec<Annotation> {
    let (instances, categories, attributes) = (table("instance"), table("category"), table("attribute"));
    let (instances, categories, attributes) = (by_token(&instances), by_token(&categories), by_token(&attributes));
    let mut out = Vec::new();
    for row in table("sample_annotation") {
        let instance = row["instance_token"].as_str().unwrap();
        let category = instances[instance]["category_token"].as_str().unwrap();
        if !categories[category]["name"].as_str().unwrap().starts_with("vehicle.") {
            continue;
        }
        let labels: Vec<&str> = row["attribute_tokens"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| attributes[t.as_str().unwrap()]["name"].as_str().unwrap())
            .collect();
        let motion = if labels.contains(&"vehicle.moving") {
            Motion::Moving
        } else if labels.iter().any(|l| *l == "vehicle.parked" || *l == "vehicle.stopped") {
            Motion::Still
        } else {
            continue;
        };
        let numbers =
            |key: &str| -> Vec<f64> { row[key].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
        let (t, q, size) = (numbers("translation"), numbers("rotation"), numbers("size"));
        out.push(Annotation {
            instance: instance.to_owned(),
            sample: row["sample_token"].as_str().unwrap().to_owned(),
            motion,
            centre: DVec3::new(t[0], t[1], t[2]),
            yaw: dggt_geom::glam::DQuat::from_xyzw(q[1], q[2], q[3], q[0]).to_euler(dggt_geom::glam::EulerRot::ZYX).0,
            size: DVec3::new(size[1], size[0], size[2]),
        });
    }
    out
}

/// Per sample token: its time (µs) and each camera channel's key-frame time (µs).
fn sample_times() -> (HashMap<String, i64>, HashMap<(String, String), i64>) {
    let samples = table("sample");
    let sample_time =
        samples.iter().map(|s| (s["token"].as_str().unwrap().to_owned(), s["timestamp"].as_i64().unwrap())).collect();
    let mut camera_time = HashMap::new();
    for row in table("sample_data") {
        let file = row["filename"].as_str().unwrap();
        let Some(channel) = file.split('/').nth(1).filter(|c| c.starts_with("CAM_")) else { continue };
        let key = (row["sample_token"].as_str().unwrap().to_owned(), channel.to_owned());
        camera_time.insert(key, row["timestamp"].as_i64().unwrap());
    }
    (sample_time, camera_time)
}

/// A track's centre at `time_us`: linear between its annotations, continued from the nearest interval outside.
fn centre_at(track: &[(i64, DVec3)], time_us: i64) -> DVec3 {
    if track.len() == 1 {
        return track[0].1;
    }
    let after = track.partition_point(|(t, _)| *t <= time_us).clamp(1, track.len() - 1);
    let ((t0, a), (t1, b)) = (track[after - 1], track[after]);
    a.lerp(b, (time_us - t0) as f64 / (t1 - t0) as f64)
}

fn matrix(path: &Path) -> DMat4 {
    DMat4::from_cols_array_2d(&text::read_matrix::<4, 4>(path).unwrap()).transpose()
}

/// Whether a vehicle's centre is what its camera sees there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Sight {
    Visible,
    /// Behind a nearer vehicle's box.
    Hidden,
}

/// How many vehicle views of each kind have their centre inside the image, and how many of those fall on a
/// dynamic pixel.
#[derive(Debug, Default)]
struct Coverage {
    views: HashMap<(Motion, Sight), usize>,
    dynamic: HashMap<(Motion, Sight), usize>,
    /// Per sight, the views whose instance mask shows the vehicle's own key at its centre.
    own_instance: HashMap<Sight, usize>,
}

impl Coverage {
    fn fraction(&self, motion: Motion, sight: Sight) -> f64 {
        let key = (motion, sight);
        self.dynamic.get(&key).copied().unwrap_or(0) as f64 / self.views[&key] as f64
    }

    fn count(&self, motion: Motion, sight: Sight) -> usize {
        self.views.get(&(motion, sight)).copied().unwrap_or(0)
    }

    /// The share of views (moving and still) whose instance mask shows the vehicle itself at its centre.
    fn own_instance(&self, sight: Sight) -> f64 {
        let views: usize = [Motion::Moving, Motion::Still].iter().map(|&m| self.count(m, sight)).sum();
        self.own_instance.get(&sight).copied().unwrap_or(0) as f64 / views as f64
    }

    /// The fraction over visible and hidden views together.
    fn overall(&self, motion: Motion) -> f64 {
        let of = |map: &HashMap<(Motion, Sight), usize>| {
            [Sight::Visible, Sight::Hidden].iter().map(|&s| map.get(&(motion, s)).copied().unwrap_or(0)).sum::<usize>()
        };
        of(&self.dynamic) as f64 / of(&self.views) as f64
    }
}

fn convert(style: DynamicMaskStyle, out: &Path) {
    let tables = Tables::read(&root(), &NuScenesVersion::Other(VERSION.into())).unwrap();
    let options = NuScenesOptions {
        cameras: (0..6).collect(),
        sky_masks: SkyMasks::None,
        depth_flows: DepthFlows::None,
        dynamic_masks: style,
        rate: FrameRate::KeyFrames,
    };
    let summary = convert_scene(&tables, 0, out, &options, &|_| {}).unwrap();
    assert_eq!(summary.frames, 40, "the sequence's 40 frames converted");
}

/// The dynamic-mask coverage at every vehicle's centre, at each camera's own time, over the 40 x 6 views.
fn coverage(out: &Path) -> Coverage {
    let layout = ExportLayout::new(out);
    let names = dggt_data::ExportVariant::NuScenes.camera_names();
    let annotations = vehicle_annotations();
    let (sample_time, camera_time) = sample_times();
    let mut tracks: HashMap<&str, Vec<(i64, DVec3)>> = HashMap::new();
    for a in &annotations {
        tracks.entry(&a.instance).or_default().push((sample_time[&a.sample], a.centre));
    }
    tracks.values_mut().for_each(|t| t.sort_by_key(|(time, _)| *time));
    let mut samples: Vec<(&String, &i64)> = sample_time.iter().collect();
    samples.sort_by_key(|(_, time)| **time);
    let frame_of: HashMap<&String, usize> = samples.iter().enumerate().map(|(t, (token, _))| (*token, t)).collect();
    let mut by_sample: HashMap<&str, Vec<&Annotation>> = HashMap::new();
    for a in &annotations {
        by_sample.entry(&a.sample).or_default().push(a);
    }
    let mut coverage = Coverage::default();
    let mut masks = HashMap::new();
    let mut instance_masks = HashMap::new();
    let key_of = instance_keys(&layout);
    for camera in 0..6 {
        let k = text::read_numbers(&layout.intrinsics(camera), 9).unwrap();
        for a in &annotations {
            let frame = frame_of[&a.sample];
            let time = camera_time[&(a.sample.clone(), names[camera].to_owned())];
            let centre = centre_at(&tracks[a.instance.as_str()], time);
            let world_from_camera = matrix(&layout.extrinsics_at(frame, camera));
            let in_camera = world_from_camera.inverse().transform_point3(centre);
            let origin = world_from_camera.transform_point3(DVec3::ZERO);
            let (direction, distance) = ((centre - origin).normalize(), (centre - origin).length());
            let hidden = by_sample[a.sample.as_str()].iter().filter(|b| b.instance != a.instance).any(|b| {
                let other = centre_at(&tracks[b.instance.as_str()], time);
                b.entry(other, origin, direction).is_some_and(|at| at < distance)
            });
            let sight = if hidden { Sight::Hidden } else { Sight::Visible };
            let mask = masks.entry((frame, camera)).or_insert_with(|| {
                images::read_gray(&layout.dynamic_mask(DynamicMaskKind::All, frame, camera)).unwrap()
            });
            let (u, v) = (k[0] * in_camera.x / in_camera.z + k[2], k[1] * in_camera.y / in_camera.z + k[3]);
            let inside = in_camera.z > 0.5 && u >= 0.0 && v >= 0.0;
            if !inside || u >= mask.width() as f64 || v >= mask.height() as f64 {
                continue;
            }
            *coverage.views.entry((a.motion, sight)).or_default() += 1;
            if mask.get_pixel(u as u32, v as u32).0[0] == 255 {
                *coverage.dynamic.entry((a.motion, sight)).or_default() += 1;
            }
            let instances = instance_masks
                .entry((frame, camera))
                .or_insert_with(|| images::read_gray16(&layout.instance_mask(frame, camera)).unwrap());
            if usize::from(instances.get_pixel(u as u32, v as u32).0[0]) == key_of[&a.instance] + 1 {
                *coverage.own_instance.entry(sight).or_default() += 1;
            }
        }
    }
    coverage
}

/// The key of each object of `instances/instances_info.json`, by its dataset id.
fn instance_keys(layout: &ExportLayout) -> HashMap<String, usize> {
    let info: Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    let info = info.as_object().expect("instances_info.json is an object");
    info.iter().map(|(key, object)| (object["id"].as_str().unwrap().to_owned(), key.parse().unwrap())).collect()
}

#[test]
fn moving_cars_are_dynamic_at_their_centres_and_parked_ones_static() {
    let dir = tempfile::tempdir().unwrap();
    convert(DynamicMaskStyle::default(), dir.path());
    let outlines = coverage(dir.path());
    report("moving outlines", &outlines);
    let (moving, still) = (Motion::Moving, Motion::Still);
    assert!(outlines.fraction(moving, Sight::Visible) >= 0.85, "visible moving vehicles dynamic at their centre");
    assert!(outlines.fraction(still, Sight::Visible) <= 0.05, "visible parked vehicles dynamic at their centre");
    assert!(outlines.overall(moving) >= 0.85, "moving vehicles, hidden ones included");
    assert!(
        outlines.count(moving, Sight::Visible) > 100 && outlines.count(still, Sight::Visible) > 300,
        "{outlines:?}"
    );
    let note = std::fs::read_to_string(dir.path().join("dynamic_masks/SOURCE.txt")).unwrap();
    assert!(note.contains("moving-outlines"), "{note}");
    // The instance masks show each vehicle, moving or parked, as itself where it is visible, and mostly the
    // nearer vehicle where it is hidden.
    assert!(outlines.own_instance(Sight::Visible) >= 0.95, "{outlines:?}");
    assert!(outlines.own_instance(Sight::Hidden) <= 0.5, "{outlines:?}");

    // drivestudio's rectangles, for the record: every box, parked ones included, and none crossing the border.
    let dir = tempfile::tempdir().unwrap();
    convert(DynamicMaskStyle::Drivestudio, dir.path());
    let rectangles = coverage(dir.path());
    report("drivestudio rectangles", &rectangles);
    assert!(rectangles.fraction(still, Sight::Visible) > 0.5, "the release's rule masks parked cars");
    assert!(outlines.overall(moving) > rectangles.overall(moving), "outlines cover more moving cars than rectangles");
}

fn report(what: &str, coverage: &Coverage) {
    println!(
        "{what}: instance masks show the vehicle itself at its centre in {:.1} % of visible views, {:.1} % of hidden",
        100.0 * coverage.own_instance(Sight::Visible),
        100.0 * coverage.own_instance(Sight::Hidden),
    );
    for (motion, name) in [(Motion::Moving, "moving"), (Motion::Still, "parked or stopped")] {
        println!(
            "{what}: {name} vehicles dynamic at their centre: {:.1} % of {} visible views, {:.1} % of {} hidden \
             behind a nearer vehicle, {:.1} % of all",
            100.0 * coverage.fraction(motion, Sight::Visible),
            coverage.count(motion, Sight::Visible),
            100.0 * coverage.fraction(motion, Sight::Hidden),
            coverage.count(motion, Sight::Hidden),
            100.0 * coverage.overall(motion),
        );
    }
}
