//! Procedural layout: from the seed to a [`SynthScene`].
//!
//! The seed drives one `StdRng` whose draws are made in a fixed order, so a configuration always produces the
//! same scene. Ranges are chosen to look like a city street and to keep every view informative:
//!
//! - the ego drives at 7-9 m/s along +x in the right-hand lane, swaying by up to 0.7 m;
//! - three moving cars, with their activity centred on the middle of the sequence: a lead car ahead in the ego
//!   lane (faster than the ego), an oncoming car that turns right into the side street along a circular arc
//!   (5.5-7.5 m/s, radius 4.5-6 m, mid-turn at the middle of the sequence), and a faster oncoming car ahead of
//!   it that passes the ego (9-12 m/s);
//! - parked cars on both parking strips, buildings on both sides (with a second, taller row behind), poles
//!   and trees on the sidewalks, all kept clear of the side street.

use std::f64::consts::{FRAC_PI_2, PI};

use dggt_geom::glam::{DVec2, DVec3};
use dggt_geom::{ImageSize, Rigid};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use crate::config::SynthConfig;
use crate::error::Result;
use crate::motion::{CarMotion, EgoMotion, Path, yaw_pose};
use crate::rig;
use crate::scene::{ObjectKind, Part, Placement, SceneObject, SynthScene};
use crate::shading::{Facade, Material};
use crate::shapes::{Aabb, Cylinder, Shape, Sphere};
use crate::street::{FACADE_OFFSET, KERB_OFFSET, LANE_WIDTH, SIDE_STREET_HALF_WIDTH, SIDEWALK_HEIGHT, Street};

const CAR_PAINT: [[f64; 3]; 9] = [
    [0.86, 0.86, 0.88],
    [0.08, 0.08, 0.09],
    [0.58, 0.60, 0.63],
    [0.68, 0.09, 0.08],
    [0.10, 0.22, 0.56],
    [0.10, 0.32, 0.19],
    [0.88, 0.72, 0.10],
    [0.30, 0.30, 0.33],
    [0.45, 0.12, 0.35],
];

const FACADE_COLOURS: [[f64; 3]; 8] = [
    [0.80, 0.72, 0.58],
    [0.62, 0.32, 0.24],
    [0.70, 0.70, 0.68],
    [0.88, 0.84, 0.74],
    [0.55, 0.60, 0.66],
    [0.76, 0.56, 0.42],
    [0.50, 0.47, 0.44],
    [0.84, 0.78, 0.64],
];

const BACKGROUND_COLOURS: [[f64; 3]; 4] =
    [[0.60, 0.64, 0.70], [0.70, 0.70, 0.72], [0.52, 0.56, 0.62], [0.76, 0.74, 0.70]];

const WINDOW_TINTS: [[f64; 3]; 4] = [[0.16, 0.22, 0.30], [0.12, 0.14, 0.18], [0.22, 0.30, 0.34], [0.20, 0.20, 0.24]];

const FOLIAGE: [[f64; 3]; 3] = [[0.18, 0.36, 0.12], [0.24, 0.40, 0.14], [0.14, 0.30, 0.16]];

/// How far past the street's ends the sidewalks continue, so that the road runs on to the horizon.
const SIDEWALK_RUN_OUT: f64 = 400.0;

fn pick(rng: &mut StdRng, palette: &[[f64; 3]], jitter: f64) -> DVec3 {
    let base = DVec3::from_array(palette[rng.random_range(0..palette.len())]);
    (base * rng.random_range(1.0 - jitter..1.0 + jitter)).clamp(DVec3::ZERO, DVec3::ONE)
}

fn boxed(min: [f64; 3], max: [f64; 3], material: Material) -> Part {
    Part { shape: Shape::Box(Aabb::new(DVec3::from_array(min), DVec3::from_array(max))), material }
}

/// A car's primitives in its box frame: a body, a cabin set back from the front, and four wheels.
/// The parts exactly fill the box `[length, width, height]` centred on the origin.
fn car_parts(length: f64, width: f64, height: f64, colour: DVec3) -> Vec<Part> {
    let (hl, hw, hh) = (length / 2.0, width / 2.0, height / 2.0);
    let (body_bottom, body_top) = (-hh + 0.30, -hh + 0.92);
    let cabin_min = DVec3::new(-0.32 * length, -0.44 * width, body_top);
    let cabin_max = DVec3::new(0.16 * length, 0.44 * width, hh);
    let mut parts = vec![
        boxed(
            [-hl, -hw, body_bottom],
            [hl, hw, body_top],
            Material::CarBody { colour, half_width: hw, bottom: body_bottom, top: body_top },
        ),
        boxed(
            cabin_min.to_array(),
            cabin_max.to_array(),
            Material::CarCabin { colour, min: cabin_min, max: cabin_max },
        ),
    ];
    for (sx, sy) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        let x = sx * 0.31 * length;
        let (y_in, y_out) = (sy * (hw - 0.25), sy * (hw - 0.02));
        let hub = DVec3::new(x, sy * hw, -hh + 0.32);
        parts.push(boxed(
            [x - 0.32, y_in.min(y_out), -hh],
            [x + 0.32, y_in.max(y_out), -hh + 0.64],
            Material::Wheel { hub },
        ));
    }
    parts
}

/// A random car body: `(parts, height)`.
fn random_car(rng: &mut StdRng) -> (Vec<Part>, f64) {
    let length = rng.random_range(4.1..4.9);
    let width = rng.random_range(1.75..1.95);
    let height = rng.random_range(1.42..1.65);
    let colour = pick(rng, &CAR_PAINT, 0.05);
    (car_parts(length, width, height, colour), height)
}

#[derive(Default)]
struct Objects(Vec<SceneObject>);

impl Objects {
    fn push(&mut self, kind: ObjectKind, parts: Vec<Part>, placement: Placement) {
        let id = self.0.len() as u32;
        self.0.push(SceneObject::new(id, kind, parts, placement));
    }

    fn push_static(&mut self, kind: ObjectKind, parts: Vec<Part>) {
        self.push(kind, parts, Placement::Fixed(Rigid::IDENTITY));
    }
}

fn moving_cars(objects: &mut Objects, rng: &mut StdRng, ego: &EgoMotion, street: &Street, duration: f64) {
    let drive = |objects: &mut Objects, rng: &mut StdRng, path: Path, speed: f64, time_at_entry: f64| {
        let (parts, height) = random_car(rng);
        let motion = CarMotion { path, speed, time_at_entry, centre_height: height / 2.0 };
        objects.push(ObjectKind::MovingCar, parts, Placement::Driving(motion));
    };
    let lead_start = DVec2::new(rng.random_range(12.0..18.0), 0.0);
    let lead_speed = ego.speed + rng.random_range(1.5..3.0);
    drive(objects, rng, Path::straight(lead_start, 0.0), lead_speed, 0.0);

    let oncoming_lane = street.y(LANE_WIDTH / 2.0);
    let radius = rng.random_range(4.5..6.0);
    let turn_speed = rng.random_range(5.5..7.5);
    let entry = DVec2::new(street.side_street_x + SIDE_STREET_HALF_WIDTH / 2.0 + radius, oncoming_lane);
    let turn = Path { entry, heading: PI, radius, turn: -FRAC_PI_2 };
    let time_at_turn = duration / 2.0 - turn.arc_length() / (2.0 * turn_speed);
    drive(objects, rng, turn, turn_speed, time_at_turn);

    let gap = rng.random_range(12.0..20.0);
    let speed = rng.random_range(9.0..12.0);
    let start = DVec2::new(entry.x - gap + speed * time_at_turn, oncoming_lane);
    drive(objects, rng, Path::straight(start, PI), speed, 0.0);
}

fn parked_cars(objects: &mut Objects, rng: &mut StdRng, street: &Street) {
    for side in [-1.0, 1.0] {
        let heading = if side < 0.0 { 0.0 } else { PI };
        let mut x = street.x_min + rng.random_range(0.0..5.0);
        while x < street.x_max - 30.0 {
            let slot = rng.random_range(6.0..8.5);
            let centre = x + slot / 2.0;
            if rng.random_bool(0.45) && !(side > 0.0 && street.near_side_street(centre, 6.0)) {
                let (parts, height) = random_car(rng);
                let yaw = heading + rng.random_range(-0.03..0.03);
                let lateral = side * (LANE_WIDTH + KERB_OFFSET) / 2.0 + rng.random_range(-0.15..0.15);
                let pose = yaw_pose(yaw, DVec3::new(centre, street.y(lateral), height / 2.0));
                objects.push(ObjectKind::ParkedCar, parts, Placement::Fixed(pose));
            }
            x += slot;
        }
    }
}

fn ground_and_sidewalks(objects: &mut Objects, street: &Street) {
    objects.push_static(ObjectKind::Ground, vec![boxed([-1e6, -1e6, -1.0], [1e6, 1e6, 0.0], Material::Ground)]);
    let (start, end) = (street.x_min - SIDEWALK_RUN_OUT, street.x_max + SIDEWALK_RUN_OUT);
    let junction = (street.side_street_x - SIDE_STREET_HALF_WIDTH, street.side_street_x + SIDE_STREET_HALF_WIDTH);
    // Under the buildings too, so that set-back facades stand on paving.
    let depth = FACADE_OFFSET + 2.0;
    for (side, spans) in [(-1.0, vec![(start, end)]), (1.0, vec![(start, junction.0), (junction.1, end)])] {
        for (x0, x1) in spans {
            let (y0, y1) = (street.y(side * KERB_OFFSET), street.y(side * depth));
            let part = boxed([x0, y0.min(y1), -0.1], [x1, y0.max(y1), SIDEWALK_HEIGHT], Material::Sidewalk);
            objects.push_static(ObjectKind::Sidewalk, vec![part]);
        }
    }
}

/// Parameters of one row of buildings along one side of the street.
struct Row {
    offset: (f64, f64),
    setback: f64,
    length: (f64, f64),
    depth: (f64, f64),
    height: (f64, f64),
    gap_probability: f64,
    gap: (f64, f64),
    palette: &'static [[f64; 3]],
}

const MAIN_ROW: Row = Row {
    offset: (FACADE_OFFSET, FACADE_OFFSET),
    setback: 2.0,
    length: (8.0, 20.0),
    depth: (8.0, 14.0),
    height: (6.0, 22.0),
    gap_probability: 0.35,
    gap: (2.0, 5.0),
    palette: &FACADE_COLOURS,
};

const BACK_ROW: Row = Row {
    offset: (24.0, 30.0),
    setback: 0.0,
    length: (12.0, 28.0),
    depth: (10.0, 18.0),
    height: (14.0, 38.0),
    gap_probability: 0.6,
    gap: (3.0, 10.0),
    palette: &BACKGROUND_COLOURS,
};

fn building_row(objects: &mut Objects, rng: &mut StdRng, street: &Street, side: f64, row: &Row) {
    let corridor =
        (street.side_street_x - SIDE_STREET_HALF_WIDTH - 0.5, street.side_street_x + SIDE_STREET_HALF_WIDTH + 0.5);
    let mut x = street.x_min - rng.random_range(0.0..6.0);
    while x < street.x_max {
        let (x0, mut x1) = (x, x + rng.random_range(row.length.0..row.length.1));
        let gap = if rng.random_bool(row.gap_probability) { rng.random_range(row.gap.0..row.gap.1) } else { 0.0 };
        x = x1 + gap;
        if side > 0.0 && x0 < corridor.1 && x1 > corridor.0 {
            x = corridor.1;
            x1 = corridor.0;
            if x1 - x0 < 4.0 {
                continue;
            }
        }
        let offset = rng.random_range(row.offset.0..=row.offset.1)
            + if rng.random_bool(0.3) { rng.random_range(0.0..=row.setback) } else { 0.0 };
        let depth = rng.random_range(row.depth.0..row.depth.1);
        let height = rng.random_range(row.height.0..row.height.1);
        let facade = Facade {
            colour: pick(rng, row.palette, 0.06),
            window_tint: pick(rng, &WINDOW_TINTS, 0.1),
            height,
            floor_height: rng.random_range(2.9..3.6),
            bay_width: rng.random_range(2.2..3.4),
            salt: rng.random(),
        };
        let (y0, y1) = (street.y(side * offset), street.y(side * (offset + depth)));
        let part = boxed([x0, y0.min(y1), 0.0], [x1, y0.max(y1), height], Material::Building(facade));
        objects.push_static(ObjectKind::Building, vec![part]);
    }
}

fn tree(rng: &mut StdRng, base: DVec2) -> Vec<Part> {
    let trunk_height = rng.random_range(2.2..3.2);
    let crown = rng.random_range(1.2..1.9);
    let trunk = Cylinder { centre: base, radius: rng.random_range(0.12..0.18), z_min: 0.0, z_max: trunk_height };
    let foliage = Material::Foliage { colour: pick(rng, &FOLIAGE, 0.1), salt: rng.random() };
    vec![
        Part { shape: Shape::Cylinder(trunk), material: Material::Bark },
        Part {
            shape: Shape::Sphere(Sphere { centre: base.extend(trunk_height + 0.6 * crown), radius: crown }),
            material: foliage,
        },
    ]
}

/// A street light: a mast, an arm reaching `side`-inwards over the road and a lamp under its end.
fn pole(rng: &mut StdRng, base: DVec2, side: f64) -> Vec<Part> {
    let height = rng.random_range(5.5..7.0);
    let mast = Cylinder { centre: base, radius: 0.09, z_min: 0.0, z_max: height };
    let tip = base.y - side * 1.8;
    vec![
        Part { shape: Shape::Cylinder(mast), material: Material::Metal },
        boxed(
            [base.x - 0.05, base.y.min(tip), height - 0.3],
            [base.x + 0.05, base.y.max(tip), height - 0.2],
            Material::Metal,
        ),
        boxed([base.x - 0.18, tip - 0.3, height - 0.42], [base.x + 0.18, tip + 0.3, height - 0.3], Material::Lamp),
    ]
}

fn street_furniture(objects: &mut Objects, rng: &mut StdRng, street: &Street) {
    for side in [-1.0, 1.0] {
        let mut x = street.x_min + rng.random_range(0.0..8.0);
        while x < street.x_max {
            if !(side > 0.0 && street.near_side_street(x, 2.0)) {
                if rng.random_bool(0.55) {
                    let parts = tree(rng, DVec2::new(x, street.y(side * 6.7)));
                    objects.push_static(ObjectKind::Tree, parts);
                } else {
                    let parts = pole(rng, DVec2::new(x, street.y(side * 5.9)), side);
                    objects.push_static(ObjectKind::Pole, parts);
                }
            }
            x += rng.random_range(8.0..14.0);
        }
    }
}

/// Builds the scene described by `config` (validated first).
pub fn generate(config: &SynthConfig) -> Result<SynthScene> {
    config.validate()?;
    let size = ImageSize::new(config.width, config.height)?;
    let intrinsics = rig::intrinsics(size)?;
    let rig = rig::build_rig(config.cameras)?;
    let mut rng = StdRng::seed_from_u64(config.seed);
    let duration = config.duration();
    let ego = EgoMotion {
        speed: rng.random_range(7.0..9.0),
        sway_amplitude: rng.random_range(0.15..0.35),
        sway_rate: rng.random_range(0.5..1.0),
    };
    let travel = ego.speed * duration;
    let street = Street::new(travel / 2.0 + rng.random_range(20.0..28.0), -25.0, travel + 160.0);
    let sky_salt = rng.random();

    let mut objects = Objects::default();
    moving_cars(&mut objects, &mut rng, &ego, &street, duration);
    parked_cars(&mut objects, &mut rng, &street);
    ground_and_sidewalks(&mut objects, &street);
    for row in [&MAIN_ROW, &BACK_ROW] {
        for side in [-1.0, 1.0] {
            building_row(&mut objects, &mut rng, &street, side, row);
        }
    }
    street_furniture(&mut objects, &mut rng, &street);

    let ego_pose_rows: Vec<[[f64; 4]; 4]> =
        (0..config.frames).map(|frame| ego.pose(SynthConfig::frame_time(frame)).to_rows()).collect();
    let world_from_ego = ego_pose_rows.iter().map(|rows| Rigid::from_rows(*rows)).collect::<Result<Vec<_>, _>>()?;
    Ok(SynthScene {
        config: *config,
        size,
        intrinsics,
        rig,
        ego_pose_rows,
        world_from_ego,
        street,
        objects: objects.0,
        sky_salt,
    })
}
