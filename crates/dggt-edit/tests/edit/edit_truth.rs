//! Edits of a scene whose Gaussians are the generator's ground truth (`common::oracle`), compared with the
//! generator's own renders of the same scene without the object, with the object moved, and with the pose an
//! inserted object was asked for: the edits are right where nothing but the edit can be wrong.

use std::collections::BTreeMap;

use crate::common::{box_around, colours, largest_parked_car, masked_psnr, object_mask, oracle, synth, target, truth};
use burn::tensor::Device;
use dggt_edit::object::tensors;
use dggt_edit::{Edit, EditedScene, apply_edits};
use dggt_geom::PixelConvention;
use dggt_geom::glam::DVec3;
use dggt_scene::{AssembledGaussians, Scene4d, render_assembled, save_scene};
use dggt_synth::{ObjectEdit, SynthScene, WorldChange};

const FRAMES: [usize; 4] = [0, 4, 8, 12];
/// The moving cars of seed 0.
const CARS: [u32; 3] = [0, 1, 2];

/// Per car, the instance most of its pixels belong to over the input views, and the share they make up.
fn instance_of_cars(synth: &SynthScene, scene: &Scene4d) -> BTreeMap<u32, (u32, f64)> {
    let found = scene.pixels.instances().unwrap();
    CARS.iter()
        .map(|&car| {
            let mut votes: BTreeMap<Option<usize>, usize> = BTreeMap::new();
            for (view, &frame) in FRAMES.iter().enumerate() {
                for (pixel, _) in object_mask(synth, frame, car).iter().enumerate().filter(|(_, m)| **m) {
                    *votes.entry(found.instance_of(view, pixel)).or_default() += 1;
                }
            }
            let total: usize = votes.values().sum();
            let (instance, count) = votes.into_iter().max_by_key(|(_, count)| *count).unwrap();
            let id = found.instances[instance.expect("most of a car's pixels are an instance's")].id;
            (car, (id, count as f64 / total as f64))
        })
        .collect()
}

#[test]
fn each_moving_car_is_one_instance_and_each_instance_one_car() {
    let synth = synth(0, 13);
    let scene = oracle(&synth, &FRAMES, &Device::flex());
    let found = scene.pixels.instances().unwrap();
    assert_eq!(found.len(), CARS.len(), "one instance per moving car");
    let cars = instance_of_cars(&synth, &scene);
    // Purity: the share of an instance's pixels that are its car's.
    let masks: Vec<Vec<Vec<bool>>> =
        FRAMES.iter().map(|&frame| CARS.iter().map(|&car| object_mask(&synth, frame, car)).collect()).collect();
    for (&car, &(id, coverage)) in &cars {
        let (mut own, mut all) = (0usize, 0usize);
        for (view, masks) in masks.iter().enumerate() {
            for pixel in (0..scene.pixels.per_view()).filter(|&p| found.instance_of(view, p) == Some(id as usize)) {
                all += 1;
                own += usize::from(masks[car as usize][pixel]);
            }
        }
        let purity = own as f64 / all as f64;
        eprintln!("car {car}: instance {id}, {coverage:.3} of its pixels, purity {purity:.3} of {all}");
        assert!(coverage >= 0.9 && purity >= 0.98, "car {car}: coverage {coverage:.3}, purity {purity:.3}");
    }
    let mut ids: Vec<u32> = cars.values().map(|(id, _)| *id).collect();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), CARS.len(), "different cars are different instances: {cars:?}");
}

/// PSNR on `mask` of the render before and after `edited`'s edits against `truth` at `frame`.
fn before_and_after(
    edited: &EditedScene,
    synth: &SynthScene,
    frame: usize,
    truth: &[f32],
    mask: &[bool],
) -> (f64, f64) {
    let view = target(synth, frame);
    let before = colours(edited.original.render(&view).unwrap());
    let after = colours(edited.render(&view).unwrap());
    (masked_psnr(&before, truth, mask), masked_psnr(&after, truth, mask))
}

#[test]
fn removing_a_car_brings_its_region_closer_to_the_scene_without_it() {
    let device = Device::flex();
    let synth = synth(0, 13);
    let scene = oracle(&synth, &FRAMES, &device);
    let cars = instance_of_cars(&synth, &scene);
    for car in [0, 2] {
        let id = cars[&car].0;
        let edited = apply_edits(scene.clone(), &[Edit::remove(&id.to_string()).unwrap()], &device).unwrap();
        let without = synth.edited(&[ObjectEdit::Remove(car)]).unwrap();
        let mut gains = Vec::new();
        // Input frames and frames between them.
        for frame in [2, 4, 6, 8] {
            let mask = object_mask(&synth, frame, car);
            let (before, after) = before_and_after(&edited, &synth, frame, &truth(&without, frame), &mask);
            eprintln!("remove car {car} (instance {id}), frame {frame}: {before:.2} -> {after:.2} dB on its pixels");
            assert!(after > before, "car {car}, frame {frame}: {before:.2} -> {after:.2} dB");
            gains.push(after - before);
        }
        let mean = gains.iter().sum::<f64>() / gains.len() as f64;
        assert!(mean >= 1.5, "car {car}: removal gains only {mean:.2} dB on average");
    }
}

#[test]
fn moving_a_car_matches_the_scene_with_it_moved() {
    let device = Device::flex();
    let synth = synth(0, 13);
    let scene = oracle(&synth, &FRAMES, &device);
    let (car, offset) = (2, DVec3::new(0.0, 3.0, 0.0));
    let id = instance_of_cars(&synth, &scene)[&car].0;
    let edit = Edit::moved(&format!("{id}:{},{},{},0", offset.x, offset.y, offset.z)).unwrap();
    let edited = apply_edits(scene, &[edit], &device).unwrap();
    let moved = synth.edited(&[ObjectEdit::Move { object: car, change: WorldChange::translation(offset) }]).unwrap();
    for frame in [4, 6, 8] {
        let mask: Vec<bool> =
            object_mask(&synth, frame, car).iter().zip(object_mask(&moved, frame, car)).map(|(a, b)| *a || b).collect();
        let (before, after) = before_and_after(&edited, &synth, frame, &truth(&moved, frame), &mask);
        eprintln!("move car {car} by {offset}, frame {frame}: {before:.2} -> {after:.2} dB on its old and new pixels");
        assert!(after >= before + 1.0 && after >= 16.0, "frame {frame}: {before:.2} -> {after:.2} dB");
    }
}

#[test]
fn removing_a_parked_car_by_its_box_brings_its_region_closer_to_the_scene_without_it() {
    let device = Device::flex();
    let synth = synth(0, 13);
    let scene = oracle(&synth, &FRAMES, &device);
    let frame = 4;
    let parked = largest_parked_car(&synth, frame);
    let edited = apply_edits(scene, &[Edit::remove_box(&box_around(parked)).unwrap()], &device).unwrap();
    let without = synth.edited(&[ObjectEdit::Remove(parked.id())]).unwrap();
    let mask = object_mask(&synth, frame, parked.id());
    let (before, after) = before_and_after(&edited, &synth, frame, &truth(&without, frame), &mask);
    // What no view saw behind a parked car stays a hole; the rest of its region improves.
    let view = target(&synth, frame);
    let alpha = |render: dggt_scene::ViewRender| -> Vec<f32> { render.alpha.into_data().try_into_vec().unwrap() };
    let (alpha_before, alpha_after) =
        (alpha(edited.original.render(&view).unwrap()), alpha(edited.render(&view).unwrap()));
    let holes = mask
        .iter()
        .zip(alpha_before.iter().zip(&alpha_after))
        .filter(|(m, (b, a))| **m && **b >= 0.5 && **a < 0.5)
        .count();
    let pixels = mask.iter().filter(|m| **m).count();
    eprintln!(
        "remove parked car {} by its box, frame {frame}: {before:.2} -> {after:.2} dB on its {pixels} pixels, {holes} of them holes",
        parked.id()
    );
    assert!(after >= before + 0.5, "{before:.2} -> {after:.2} dB");
    assert!(holes > 0 && holes < pixels, "{holes} holes among {pixels} pixels");
}

#[test]
fn an_inserted_car_shows_where_it_was_put() {
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    let (destination, source) = (synth(0, 13), synth(1, 13));
    let scene = oracle(&destination, &FRAMES, &device);
    let other = oracle(&source, &FRAMES, &device);
    let file = dir.path().join("other.safetensors");
    save_scene(&other, &file).unwrap();
    // On the road where the ray through pixel (48, 41) of frame 0 meets it, raised to a car's middle.
    let view = target(&destination, 0);
    let (k, pose) = (view.camera.intrinsics, view.camera.world_from_camera);
    let pixel = PixelConvention::Centred.coordinates(48, 41);
    let ray = pose.transform_vector(DVec3::new((pixel.x - k.cx) / k.fx, (pixel.y - k.cy) / k.fy, 1.0));
    let position = destination.cast(pose.translation(), ray, 0.0).unwrap().point + DVec3::Z * 0.8;
    let source_car = &other.pixels.instances().unwrap().instances[0];
    let (first, reference) = (source_car.appearances[0].time, source_car.trajectory.reference_centre());
    let yaw = 30.0;
    let text = format!("{}:{}@{},{},{},{yaw}", file.display(), source_car.id, position.x, position.y, position.z);
    let edited = apply_edits(scene.clone(), &[Edit::insert(&text).unwrap()], &device).unwrap();

    // At its first appearance's time the object is its source points carried rigidly: centre on the position,
    // offsets turned by the yaw about this world's up (after the source's up is turned onto it).
    let cloud = edited.carried[0].cloud_at(first);
    let rotation =
        edited.up.yaw(yaw) * edited.up.turn_from(dggt_edit::frame::WorldUp::of_camera(&other.views()[0].camera));
    let points: Vec<DVec3> = cloud.means.iter().map(|m| DVec3::from_array(m.map(f64::from))).collect();
    let centre = points.iter().sum::<DVec3>() / points.len() as f64;
    assert!(centre.abs_diff_eq(position, 1e-4), "centre {centre} vs {position}");
    let first_source = source_points_at_first(&other);
    for (drawn, original) in points.iter().zip(&first_source) {
        assert!(drawn.abs_diff_eq(position + rotation * (*original - reference), 1e-3), "{drawn} vs {original}");
    }

    // Rendered alone from the destination's camera at that time, its mask's centroid is the position's pixel.
    let view = target(&destination, (first * 10.0).round() as usize);
    let assembled = AssembledGaussians { gaussians: tensors(&cloud, &device), counts: Default::default() };
    let alpha: Vec<f32> = render_assembled(&assembled, None, &view, scene.pixels.size, &scene.assembly)
        .unwrap()
        .alpha
        .into_data()
        .try_into_vec()
        .unwrap();
    let width = scene.pixels.size.width as usize;
    let mass: f64 = alpha.iter().map(|&a| a as f64).sum();
    let centroid = alpha.iter().enumerate().fold([0.0; 2], |[x, y], (i, &a)| {
        [x + a as f64 * ((i % width) as f64 + 0.5), y + a as f64 * ((i / width) as f64 + 0.5)]
    });
    let (x, y) = (centroid[0] / mass, centroid[1] / mass);
    let expected =
        view.camera.intrinsics.project(view.camera.world_from_camera.inverse().transform_point(position)).unwrap();
    let distance = ((x - expected.x).powi(2) + (y - expected.y).powi(2)).sqrt();
    eprintln!(
        "inserted car: mask centroid ({x:.2}, {y:.2}), the position projects to ({:.2}, {:.2}): {distance:.2} px",
        expected.x, expected.y
    );
    assert!(mass > 50.0, "the inserted car covers {mass:.1} pixels");
    assert!(distance <= 1.0, "the mask's centroid is {distance:.2} px from the position's projection");
}

fn source_means(scene: &Scene4d) -> Vec<f32> {
    scene.pixels.means.clone().into_data().try_into_vec().unwrap()
}

/// The points of instance 0 of `scene` at its first appearance, in pixel order.
fn source_points_at_first(scene: &Scene4d) -> Vec<DVec3> {
    let found = scene.pixels.instances().unwrap();
    let means = source_means(scene);
    let per_view = scene.pixels.per_view();
    found.instances[0].appearances[0]
        .views
        .iter()
        .flat_map(|&view| {
            let labels = found.labels(view);
            (0..per_view).filter(move |&p| labels[p] == 0).map(move |p| view * per_view + p)
        })
        .map(|row| DVec3::from_array(std::array::from_fn(|k| means[row * 3 + k] as f64)))
        .collect()
}
