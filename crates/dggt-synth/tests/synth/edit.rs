//! Edited scenes against the scene they were made from: a removed object leaves its pixels, masks, depth, flow,
//! lidar returns and instance lists and nothing else; a moved object is met where the rigid change puts it, with
//! its velocity turned by the change; invalid edits are errors; edits are reproducible.

use std::f64::consts::FRAC_PI_2;

use dggt_data::{ExportLayout, ExportVariant};
use dggt_geom::glam::DVec3;
use dggt_geom::{PixelConvention, Rigid};
use dggt_synth::{
    MoveFlag, ObjectEdit, ObjectId, ObjectKind, Presence, RenderedView, SynthConfig, SynthError, SynthScene,
    WorldChange, generate, write_export,
};

/// The lead car, ahead of the ego in its lane: seen by the FRONT camera.
const LEAD_CAR: ObjectId = 0;
/// The car that turns into the side street, mid-turn at the middle of the sequence.
const TURNING_CAR: ObjectId = 1;

fn scene() -> SynthScene {
    generate(&SynthConfig { seed: 3, frames: 20, cameras: 3, width: 64, height: 48 }).unwrap()
}

/// The world ray through the centre of pixel `(col, row)`: `(origin, unit direction)`.
fn pixel_ray(scene: &SynthScene, frame: usize, camera: usize, col: u32, row: u32) -> (DVec3, DVec3) {
    let pose = scene.world_from_camera(frame, camera).unwrap();
    let k = scene.intrinsics();
    let p = PixelConvention::Centred.coordinates(col, row);
    let direction = DVec3::new((p.x - k.cx) / k.fx, (p.y - k.cy) / k.fy, 1.0);
    (pose.translation(), pose.transform_vector(direction).normalize())
}

/// The pixel rectangle `[col0, col1] x [row0, row1]` holding the projection of the object's box, grown by one
/// pixel. The box must lie in front of the camera.
fn projected_box(scene: &SynthScene, object: ObjectId, frame: usize, camera: usize) -> [i64; 4] {
    let object = scene.object(object).unwrap();
    let camera_from_world = scene.world_from_camera(frame, camera).unwrap().inverse();
    let world_from_object = object.world_from_object(SynthConfig::frame_time(frame));
    let half = DVec3::from_array(object.box_size()) / 2.0;
    let k = scene.intrinsics();
    let mut rect = [i64::MAX, i64::MAX, i64::MIN, i64::MIN];
    for corner in 0..8 {
        let sign = |bit: usize| if corner & bit == 0 { -1.0 } else { 1.0 };
        let local = half * DVec3::new(sign(1), sign(2), sign(4));
        let c = camera_from_world.transform_point(world_from_object.transform_point(local));
        assert!(c.z > 0.1, "the box is in front of the camera");
        let (col, row) = ((k.fx * c.x / c.z + k.cx).floor() as i64, (k.fy * c.y / c.z + k.cy).floor() as i64);
        rect = [rect[0].min(col - 1), rect[1].min(row - 1), rect[2].max(col + 1), rect[3].max(row + 1)];
    }
    rect
}

fn outside(rect: [i64; 4], col: u32, row: u32) -> bool {
    let (col, row) = (col as i64, row as i64);
    col < rect[0] || col > rect[2] || row < rect[1] || row > rect[3]
}

/// A ray from half a metre above the middle of the object's roof, straight down: `(origin, direction)`.
fn ray_onto_roof(scene: &SynthScene, object: ObjectId, time: f64) -> (DVec3, DVec3) {
    let object = scene.object(object).unwrap();
    let top = object.centre(time) + DVec3::Z * (object.box_size()[2] / 2.0 + 0.5);
    (top, DVec3::new(0.05, -0.03, -1.0))
}

/// The first object of `kind`.
fn first(scene: &SynthScene, kind: ObjectKind) -> ObjectId {
    scene.objects().iter().find(|o| o.kind() == kind).unwrap().id()
}

/// `v` turned by `yaw` radians counter-clockwise about +z.
fn turn(yaw: f64, v: DVec3) -> DVec3 {
    DVec3::new(yaw.cos() * v.x - yaw.sin() * v.y, yaw.sin() * v.x + yaw.cos() * v.y, v.z)
}

#[test]
fn removing_the_lead_car_shows_what_is_behind_it_and_leaves_the_rest_of_the_view_alone() {
    let (frame, camera) = (10, 0);
    let scene = scene();
    let edited = scene.edited(&[ObjectEdit::Remove(LEAD_CAR)]).unwrap();
    let (before, after) = (scene.render_view(frame, camera).unwrap(), edited.render_view(frame, camera).unwrap());
    assert!(before.visible_instances.contains(&LEAD_CAR));
    assert!(!after.visible_instances.contains(&LEAD_CAR));
    assert!(before.visible_instances.iter().all(|id| *id == LEAD_CAR || after.visible_instances.contains(id)));
    assert!(edited.instances().all(|o| o.id() != LEAD_CAR) && edited.object(LEAD_CAR).is_some_and(|o| !o.is_drawn()));

    let time = SynthConfig::frame_time(frame);
    let rect = projected_box(&scene, LEAD_CAR, frame, camera);
    let mut uncovered = 0;
    for (col, row, _) in before.image.enumerate_pixels() {
        let (origin, dir) = pixel_ray(&scene, frame, camera, col, row);
        let hit_before = scene.cast(origin, dir, time);
        if hit_before.is_some_and(|hit| hit.object == LEAD_CAR) {
            uncovered += 1;
            let behind = edited.cast(origin, dir, time);
            assert!(behind.is_none_or(|hit| hit.object != LEAD_CAR && hit.distance > hit_before.unwrap().distance));
            assert_eq!(before.dynamic_mask.get_pixel(col, row).0, [255]);
            assert_eq!(after.dynamic_mask.get_pixel(col, row).0, [0], "nothing dynamic behind the car at {col},{row}");
            assert_ne!(before.image.get_pixel(col, row), after.image.get_pixel(col, row));
        }
        if outside(rect, col, row) {
            assert_eq!(before.image.get_pixel(col, row), after.image.get_pixel(col, row), "colour at {col},{row}");
            for (a, b) in masks(&before).into_iter().zip(masks(&after)) {
                assert_eq!(a.get_pixel(col, row), b.get_pixel(col, row), "mask at {col},{row}");
            }
        }
    }
    assert!(uncovered >= 10, "the lead car covers {uncovered} pixels");
    assert_depth_flow_changes_only_inside(&before, &after, rect);
}

fn masks(view: &RenderedView) -> [&image::GrayImage; 3] {
    [&view.sky_mask, &view.dynamic_mask, &view.dynamic_box_mask]
}

/// Depth-flow samples outside `rect` are bit-identical; inside, some are deeper (or sky) and none nearer.
fn assert_depth_flow_changes_only_inside(before: &RenderedView, after: &RenderedView, rect: [i64; 4]) {
    let [_, cols, channels] = before.depth_flow_shape;
    let mut deeper = 0;
    for (i, (a, b)) in before.depth_flow.chunks(channels).zip(after.depth_flow.chunks(channels)).enumerate() {
        let (col, row) = ((4 * (i % cols) + 2) as u32, (4 * (i / cols) + 2) as u32);
        if outside(rect, col, row) {
            assert_eq!(
                a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                b.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                "sample {i} outside the edited box unchanged"
            );
        } else if a != b {
            assert!(b[0] == 0.0 || b[0] > a[0], "sample {i}: depth {} -> {}", a[0], b[0]);
            deeper += 1;
        }
    }
    assert!(deeper > 0, "some depth-flow sample saw the car");
}

#[test]
fn a_removed_car_gives_no_lidar_returns_and_no_instance() {
    let frame = 10;
    let scene = scene();
    let edited = scene.edited(&[ObjectEdit::Remove(LEAD_CAR)]).unwrap();
    let car = scene.object(LEAD_CAR).unwrap();
    let object_from_ego =
        car.world_from_object(SynthConfig::frame_time(frame)).inverse() * scene.world_from_ego(frame).unwrap();
    // Inside the box, or on its faces, but above the road the car stands on.
    let half = DVec3::from_array(car.box_size()) / 2.0 + 1e-6;
    let on_car = |points: &[dggt_data::lidar::LidarPoint]| {
        let inside = |p: DVec3| p.abs().cmple(half).all() && p.z > 0.01 - half.z;
        points.iter().filter(|p| inside(object_from_ego.transform_point(p.point))).count()
    };
    assert!(on_car(&dggt_synth::lidar::sweep(&scene, frame).unwrap()) > 0);
    assert_eq!(on_car(&dggt_synth::lidar::sweep(&edited, frame).unwrap()), 0);

    let dir = tempfile::tempdir().unwrap();
    let summary = write_export(&edited, dir.path(), ExportVariant::Waymo, dggt_synth::Sweeps::Skip).unwrap();
    assert_eq!((summary.removed_objects, summary.moved_objects), (vec![LEAD_CAR], vec![]));
    assert_eq!(summary.instances, scene.instances().count() - 1);
    let layout = ExportLayout::new(dir.path());
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    assert!(info.get(LEAD_CAR.to_string()).is_none() && info.get(TURNING_CAR.to_string()).is_some());
    let description: serde_json::Value =
        serde_json::from_slice(&std::fs::read(layout.synth_description()).unwrap()).unwrap();
    assert_eq!(description["edits"]["objects"], serde_json::json!([{ "remove": LEAD_CAR }]));
    assert!(description["command"].as_str().unwrap().ends_with("--remove-object 0"), "{}", description["command"]);
}

#[test]
fn a_static_object_moved_by_an_offset_is_met_where_the_offset_puts_it() {
    let scene = scene();
    let time = SynthConfig::frame_time(5);
    let objects = [ObjectKind::ParkedCar, ObjectKind::Tree, ObjectKind::Building].map(|kind| first(&scene, kind));
    let offset = DVec3::new(0.7, -0.4, 0.2);
    let edits = objects.map(|object| ObjectEdit::Move { object, change: WorldChange::translation(offset) });
    let moved = scene.edited(&edits).unwrap();
    for object in objects {
        let (origin, dir) = ray_onto_roof(&scene, object, time);
        let hit = scene.cast(origin, dir, time).unwrap();
        let moved_hit = moved.cast(origin + offset, dir, time).unwrap();
        assert_eq!((hit.object, moved_hit.object), (object, object));
        assert!(
            moved_hit.point.abs_diff_eq(hit.point + offset, 1e-9),
            "{object}: {} vs {}",
            moved_hit.point,
            hit.point
        );
        assert!(moved_hit.normal.abs_diff_eq(hit.normal, 1e-12) && moved_hit.velocity == DVec3::ZERO);
        let centre = scene.object(object).unwrap().centre(time);
        assert!(moved.object(object).unwrap().centre(time).abs_diff_eq(centre + offset, 1e-12));
        assert_eq!(moved.object(object).unwrap().presence(), Presence::Moved(WorldChange::translation(offset)));
    }
}

#[test]
fn a_static_object_turned_about_a_pivot_has_its_centre_and_surfaces_turned() {
    let scene = scene();
    let time = SynthConfig::frame_time(5);
    let object = first(&scene, ObjectKind::ParkedCar);
    let centre = scene.object(object).unwrap().centre(time);
    let (yaw, pivot, offset) = (0.6, centre + DVec3::new(2.0, -1.0, 0.3), DVec3::new(1.0, 0.5, 0.0));
    let change = WorldChange { offset, yaw, pivot };
    let moved = scene.edited(&[ObjectEdit::Move { object, change }]).unwrap();
    let expected = turn(yaw, centre - pivot) + pivot + offset;
    assert!(moved.object(object).unwrap().centre(time).abs_diff_eq(expected, 1e-12));

    let (origin, dir) = ray_onto_roof(&scene, object, time);
    let hit = scene.cast(origin, dir, time).unwrap();
    let moved_hit = moved.cast(change.apply(origin), turn(yaw, dir), time).unwrap();
    assert_eq!(moved_hit.object, object);
    assert!(moved_hit.point.abs_diff_eq(change.apply(hit.point), 1e-9));
    assert!(moved_hit.normal.abs_diff_eq(turn(yaw, hit.normal), 1e-12));
}

#[test]
fn a_moving_car_moved_keeps_its_scene_flow_under_an_offset_and_turns_it_with_a_yaw() {
    let scene = scene();
    let time = scene.config().duration() / 2.0;
    let car = scene.object(TURNING_CAR).unwrap();
    assert!(car.state(time).unwrap().yaw_rate.abs() > 0.5, "the car is turning");
    let (origin, dir) = ray_onto_roof(&scene, TURNING_CAR, time);
    let hit = scene.cast(origin, dir, time).unwrap();
    assert!(hit.object == TURNING_CAR && hit.dynamic);

    let shift = WorldChange::translation(DVec3::new(-2.0, 1.5, 0.0));
    let turned = WorldChange {
        offset: DVec3::new(0.5, 0.0, 0.0),
        yaw: FRAC_PI_2 / 3.0,
        pivot: car.centre(time) + DVec3::new(1.0, 1.0, 0.0),
    };
    for change in [shift, turned] {
        let moved = scene.edited(&[ObjectEdit::Move { object: TURNING_CAR, change }]).unwrap();
        let moved_hit = moved.cast(change.apply(origin), turn(change.yaw, dir), time).unwrap();
        assert!(moved_hit.object == TURNING_CAR && moved_hit.dynamic);
        assert!(moved_hit.point.abs_diff_eq(change.apply(hit.point), 1e-9));
        let velocity = turn(change.yaw, hit.velocity);
        assert!(moved_hit.velocity.abs_diff_eq(velocity, 1e-9), "{} vs {velocity}", moved_hit.velocity);
        let state = moved.object(TURNING_CAR).unwrap().state(time).unwrap();
        assert!(state.velocity.abs_diff_eq(turn(change.yaw, car.state(time).unwrap().velocity), 1e-12));
        assert!(state.position.abs_diff_eq(change.apply(car.centre(time)), 1e-12));
    }
}

#[test]
fn the_command_line_of_an_edited_scene_reproduces_its_edits() {
    let scene = scene();
    let pivot = DVec3::new(30.0, -4.0, 0.0);
    let change = WorldChange { offset: DVec3::new(1.25, -0.5, 0.0), yaw: 0.3, pivot };
    let edited = scene.edited(&[ObjectEdit::Remove(5), ObjectEdit::Move { object: TURNING_CAR, change }]).unwrap();
    let line = edited.command_line();
    assert!(line.starts_with(&scene.config().command_line()) && line.contains(" --remove-object 5"), "{line}");
    let flag = line.split(" --move-object ").nth(1).unwrap().split(' ').next().unwrap();
    let flag: MoveFlag = flag.parse().unwrap();
    let edit = flag.edit(&scene).unwrap();
    let replayed = scene.edited(&[ObjectEdit::Remove(5), edit]).unwrap();
    for time in [0.0, 0.7, 1.9] {
        let (a, b) = (edited.object(TURNING_CAR).unwrap(), replayed.object(TURNING_CAR).unwrap());
        assert!(a.world_from_object(time).max_abs_difference(&b.world_from_object(time)) < 1e-8);
    }
}

#[test]
fn moving_twice_composes_and_editing_nothing_changes_nothing() {
    let scene = scene();
    let first_move = WorldChange { offset: DVec3::new(1.0, 0.0, 0.0), yaw: 0.2, pivot: DVec3::new(5.0, 1.0, 0.0) };
    let second_move = WorldChange { offset: DVec3::new(0.0, -1.0, 0.0), yaw: -0.5, pivot: DVec3::ZERO };
    let object = first(&scene, ObjectKind::Tree);
    let once = scene.edited(&[ObjectEdit::Move { object, change: first_move }]).unwrap();
    let twice = once.edited(&[ObjectEdit::Move { object, change: second_move }]).unwrap();
    let centre = scene.object(object).unwrap().centre(0.0);
    let expected = second_move.apply(first_move.apply(centre));
    assert!(twice.object(object).unwrap().centre(0.0).abs_diff_eq(expected, 1e-12));
    assert_eq!(twice.edits().len(), 1);
    let unedited = scene.edited(&[]).unwrap();
    assert!(unedited.edits().is_empty() && unedited.command_line() == scene.config().command_line());
    assert_views_identical(&scene.render_view(3, 1).unwrap(), &unedited.render_view(3, 1).unwrap());
}

#[test]
fn unknown_removed_conflicting_and_non_finite_edits_are_errors_naming_the_object() {
    let scene = scene();
    let count = scene.objects().len() as ObjectId;
    let shift = WorldChange::translation(DVec3::X);
    let message = |result: Result<SynthScene, SynthError>| result.unwrap_err().to_string();

    let unknown = scene.edited(&[ObjectEdit::Remove(count)]);
    assert!(matches!(unknown, Err(SynthError::UnknownObject { object, .. }) if object == count));
    assert!(message(scene.edited(&[ObjectEdit::Move { object: 9999, change: shift }])).contains("9999"));
    let removed = scene.edited(&[ObjectEdit::Remove(3)]).unwrap();
    assert!(matches!(removed.edited(&[ObjectEdit::Remove(3)]), Err(SynthError::RemovedObject { object: 3 })));
    assert!(matches!(
        MoveFlag { object: 3, offset: DVec3::X, yaw_deg: 0.0 }.edit(&removed),
        Err(SynthError::RemovedObject { object: 3 })
    ));

    let conflicting = [ObjectEdit::Remove(2), ObjectEdit::Move { object: 2, change: shift }];
    assert!(matches!(scene.edited(&conflicting), Err(SynthError::ConflictingEdits { object: 2 })));
    let moved_twice = [ObjectEdit::Move { object: 2, change: shift }, ObjectEdit::Move { object: 2, change: shift }];
    assert!(scene.edited(&moved_twice).is_ok(), "the very same edit twice counts once");

    for bad in [
        WorldChange { offset: DVec3::new(f64::NAN, 0.0, 0.0), ..shift },
        WorldChange { yaw: f64::INFINITY, ..shift },
        WorldChange { pivot: DVec3::splat(f64::NEG_INFINITY), ..shift },
    ] {
        let text = message(scene.edited(&[ObjectEdit::Move { object: 6, change: bad }]));
        assert!(text.contains("object 6") && text.contains("finite"), "{text}");
    }
}

#[test]
fn the_same_edits_render_byte_identical_views() {
    let scene = scene();
    let edits = [
        ObjectEdit::Remove(2),
        ObjectEdit::Move {
            object: LEAD_CAR,
            change: WorldChange { offset: DVec3::Y * 3.0, yaw: 0.4, pivot: DVec3::ZERO },
        },
    ];
    let (a, b) = (scene.edited(&edits).unwrap(), scene.edited(&edits).unwrap());
    for (frame, camera) in [(0, 0), (12, 1)] {
        assert_views_identical(&a.render_view(frame, camera).unwrap(), &b.render_view(frame, camera).unwrap());
    }
}

fn assert_views_identical(a: &RenderedView, b: &RenderedView) {
    assert_eq!(a.image, b.image, "identical images");
    assert_eq!(masks(a), masks(b), "identical masks");
    let bits = |v: &RenderedView| v.depth_flow.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(a), bits(b), "bit-identical depth and flow");
    assert_eq!(a.visible_instances, b.visible_instances, "the same visible instances");
}

#[test]
fn a_moved_car_is_exported_at_its_moved_pose() {
    let scene = scene();
    let change = WorldChange::translation(DVec3::new(0.0, 0.5, 0.0));
    let moved = scene.edited(&[ObjectEdit::Move { object: LEAD_CAR, change }]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let summary = write_export(&moved, dir.path(), ExportVariant::Waymo, dggt_synth::Sweeps::Skip).unwrap();
    assert_eq!(summary.moved_objects, vec![LEAD_CAR]);
    let layout = ExportLayout::new(dir.path());
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(layout.instances_info()).unwrap()).unwrap();
    let annotations = &info[LEAD_CAR.to_string()]["frame_annotations"];
    let frame = annotations["frame_idx"][0].as_u64().unwrap() as usize;
    let rows: [[f64; 4]; 4] = serde_json::from_value(annotations["obj_to_world"][0].clone()).unwrap();
    let written = Rigid::<dggt_geom::World, dggt_synth::Object>::from_rows(rows).unwrap();
    let generated = scene.object(LEAD_CAR).unwrap().world_from_object(SynthConfig::frame_time(frame));
    assert!(written.translation().abs_diff_eq(generated.translation() + change.offset, 1e-12));
}
