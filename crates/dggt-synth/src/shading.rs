//! Surface colours and lighting.
//!
//! Procedural textures (asphalt with lane markings, paving, facades with window grids, car paint with lights,
//! foliage), a sky with a horizon-to-zenith gradient and clouds, and a Lambertian sun plus ambient light with
//! distance haze. No shadows. Every texture is a pure function of the surface point (see [`crate::noise`]), so
//! shading holds no state and images are reproducible. Colours are display values in `[0, 1]`.

use dggt_geom::glam::{DVec2, DVec3};

use crate::noise::{fbm2, hash_unit, smoothstep, value2, value3};
use crate::street::{KERB_OFFSET, LANE_WIDTH, LINE_HALF_WIDTH, SIDE_STREET_HALF_WIDTH, Street};

/// Unit vector towards the sun (world frame: high, ahead and to the left of the ego's direction of travel).
pub fn sun_direction() -> DVec3 {
    DVec3::new(0.45, 0.35, 0.82).normalize()
}

const HORIZON: DVec3 = DVec3::new(0.80, 0.86, 0.92);
const ZENITH: DVec3 = DVec3::new(0.27, 0.49, 0.84);
const HAZE_DISTANCE: f64 = 320.0;
const MARKING: DVec3 = DVec3::new(0.92, 0.92, 0.88);

const SALT_ASPHALT: u64 = 0x5a17_0001;
const SALT_GRAIN: u64 = 0x5a17_0002;
const SALT_TILES: u64 = 0x5a17_0003;
const SALT_PAINT_WEAR: u64 = 0x5a17_0004;
const SALT_CLOUDS: u64 = 0x5a17_0005;

/// A building's facade texture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Facade {
    pub colour: DVec3,
    pub window_tint: DVec3,
    /// Height of the roof above the ground (m).
    pub height: f64,
    pub floor_height: f64,
    /// Horizontal spacing of window columns (m).
    pub bay_width: f64,
    pub salt: u64,
}

/// What a surface looks like.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Material {
    /// Road (asphalt and markings), side street and pavement, chosen from the world position.
    Ground,
    /// Paving tiles on top, concrete kerb on the sides.
    Sidewalk,
    Building(Facade),
    Metal,
    Lamp,
    Bark,
    Foliage {
        colour: DVec3,
        salt: u64,
    },
    /// Car body in object coordinates: lights on the front and rear faces, dark trim along the bottom.
    CarBody {
        colour: DVec3,
        half_width: f64,
        bottom: f64,
        top: f64,
    },
    /// The cabin box `min..max` (object coordinates): windows between painted pillars, a painted roof.
    CarCabin {
        colour: DVec3,
        min: DVec3,
        max: DVec3,
    },
    /// A tyre with a hub centred at `hub` (object coordinates) on its outer face.
    Wheel {
        hub: DVec3,
    },
}

/// A surface point in the owning object's frame and in the world.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Surface {
    pub world: DVec3,
    pub local: DVec3,
    pub local_normal: DVec3,
}

/// The unlit colour of `surface`.
pub(crate) fn albedo(material: &Material, surface: &Surface, street: &Street) -> DVec3 {
    let (p, n) = (surface.local, surface.local_normal);
    match material {
        Material::Ground => ground(surface.world, street),
        Material::Sidewalk => sidewalk(p, n),
        Material::Building(facade) => building(facade, p, n),
        Material::Metal => DVec3::new(0.33, 0.35, 0.38),
        Material::Lamp => DVec3::new(0.95, 0.93, 0.82),
        Material::Bark => DVec3::new(0.33, 0.24, 0.16) * (0.8 + 0.4 * value3(17, p * DVec3::new(8.0, 8.0, 2.0))),
        Material::Foliage { colour, salt } => {
            let leaves = 0.55 * value3(*salt, p * 3.1) + 0.45 * value3(salt.wrapping_add(1), p * 7.3);
            *colour * (0.55 + 0.8 * leaves)
        }
        Material::CarBody { colour, half_width, bottom, top } => car_body(*colour, *half_width, *bottom, *top, p, n),
        Material::CarCabin { colour, min, max } => car_cabin(*colour, *min, *max, p, n),
        Material::Wheel { hub } => {
            let radial = DVec2::new(p.x - hub.x, p.z - hub.z).length();
            if n.y.abs() > 0.5 && radial < 0.17 { DVec3::new(0.62, 0.63, 0.66) } else { DVec3::splat(0.05) }
        }
    }
}

fn asphalt(p: DVec2) -> DVec3 {
    let patches = fbm2(SALT_ASPHALT, p * 0.35, 3);
    let grain = value2(SALT_GRAIN, p * 9.0);
    let g = 0.28 + 0.08 * (patches - 0.5) + 0.05 * (grain - 0.5);
    DVec3::new(g, g, g * 1.04)
}

fn marking(p: DVec2, base: DVec3) -> DVec3 {
    let wear = value2(SALT_PAINT_WEAR, p * 3.0);
    base.lerp(MARKING, 0.75 + 0.25 * wear)
}

fn ground(world: DVec3, street: &Street) -> DVec3 {
    let p = world.truncate();
    let yr = p.y - street.centre_y;
    let along_side = p.x - street.side_street_x;
    let in_main = yr.abs() <= KERB_OFFSET;
    let in_side = yr > 0.0 && along_side.abs() <= SIDE_STREET_HALF_WIDTH;
    if !(in_main || in_side) {
        return pavement(p);
    }
    let base = asphalt(p);
    let line = |offset: f64| offset.abs() < LINE_HALF_WIDTH;
    if in_main {
        let centre_dash = line(yr) && p.x.rem_euclid(9.0) < 3.0;
        let junction = yr > 0.0 && along_side.abs() < SIDE_STREET_HALF_WIDTH;
        let edge = line(yr.abs() - LANE_WIDTH) && !junction;
        let parking_bay = yr.abs() > LANE_WIDTH && line(p.x.rem_euclid(6.5) - 0.1) && !junction;
        if centre_dash || edge || parking_bay {
            return marking(p, base);
        }
        return base;
    }
    let centre_dash = line(along_side) && yr > KERB_OFFSET + 1.0 && yr.rem_euclid(6.0) < 2.5;
    let stop_line = (yr - KERB_OFFSET - 0.5).abs() < 0.2 && along_side < 0.0;
    if centre_dash || stop_line { marking(p, base) } else { base }
}

fn pavement(p: DVec2) -> DVec3 {
    let cell = (p / 2.0).floor();
    let joint = (p / 2.0 - cell).min_element() < 0.02;
    let tile = hash_unit(SALT_TILES, cell.x as i64, cell.y as i64, 1);
    let base = DVec3::new(0.56, 0.54, 0.50) * (0.9 + 0.18 * tile);
    if joint { base * 0.7 } else { base }
}

fn sidewalk(p: DVec3, n: DVec3) -> DVec3 {
    if n.z < 0.5 {
        return DVec3::new(0.72, 0.71, 0.69) * (0.9 + 0.15 * value2(SALT_GRAIN, p.truncate() * 4.0 + p.z));
    }
    let q = p.truncate();
    let cell = q.floor();
    let joint = (q - cell).min_element() < 0.03;
    let tile = hash_unit(SALT_TILES, cell.x as i64, cell.y as i64, 2);
    let stain = fbm2(SALT_ASPHALT ^ 5, q * 0.5, 2);
    let base = DVec3::new(0.63, 0.62, 0.59) * (0.9 + 0.12 * tile + 0.12 * (stain - 0.5));
    if joint { base * 0.72 } else { base }
}

fn building(f: &Facade, p: DVec3, n: DVec3) -> DVec3 {
    if n.z > 0.5 {
        return DVec3::new(0.24, 0.23, 0.23) * (0.85 + 0.3 * value2(f.salt, p.truncate() * 0.7));
    }
    if n.z < -0.5 {
        return DVec3::splat(0.2);
    }
    let u = if n.x.abs() > 0.5 { p.y } else { p.x };
    let z = p.z;
    let stain = fbm2(f.salt, DVec2::new(u * 0.35, z * 0.5), 3);
    let wall = f.colour * (0.86 + 0.28 * stain);
    if z > f.height - 0.4 {
        return wall * 0.78;
    }
    if z < 0.45 {
        return wall * 0.55;
    }
    let floor = (z / f.floor_height).floor();
    let bay = (u / f.bay_width).floor();
    let (fu, fz) = (u / f.bay_width - bay, z / f.floor_height - floor);
    let (u0, u1, z0, z1) = if floor == 0.0 { (0.08, 0.92, 0.2, 0.85) } else { (0.26, 0.74, 0.3, 0.8) };
    let margin_u = 0.08 / f.bay_width;
    let margin_z = 0.08 / f.floor_height;
    let in_window = fu > u0 && fu < u1 && fz > z0 && fz < z1;
    let in_frame = fu > u0 - margin_u && fu < u1 + margin_u && fz > z0 - margin_z && fz < z1 + margin_z;
    if in_window {
        let pane = hash_unit(f.salt, bay as i64, floor as i64, 3);
        if pane > 0.93 {
            return DVec3::new(0.92, 0.82, 0.52);
        }
        let reflection = smoothstep(0.3, 1.0, fz) * 0.25;
        return (f.window_tint * (0.55 + 0.7 * pane)).lerp(HORIZON, reflection);
    }
    if in_frame {
        return DVec3::new(0.86, 0.85, 0.82);
    }
    wall
}

fn car_body(colour: DVec3, half_width: f64, bottom: f64, top: f64, p: DVec3, n: DVec3) -> DVec3 {
    if p.z < bottom + 0.12 {
        return DVec3::splat(0.08);
    }
    if n.x.abs() > 0.5 {
        let lateral = p.y.abs() / half_width;
        let light_band = p.z > top - 0.2 && p.z < top - 0.05;
        if light_band && lateral > 0.55 && lateral < 0.92 {
            return if n.x > 0.0 { DVec3::new(0.97, 0.96, 0.86) } else { DVec3::new(0.85, 0.06, 0.05) };
        }
        if p.z < bottom + 0.3 {
            return DVec3::splat(0.12);
        }
    }
    colour
}

fn car_cabin(colour: DVec3, min: DVec3, max: DVec3, p: DVec3, n: DVec3) -> DVec3 {
    const PILLAR: f64 = 0.12;
    let roof_edge = p.z > max.z - 0.06 || n.z.abs() > 0.5;
    let pillar = if n.y.abs() > 0.5 {
        p.x < min.x + PILLAR || p.x > max.x - PILLAR || (p.x - (min.x + max.x) / 2.0).abs() < PILLAR / 2.0
    } else {
        p.y < min.y + PILLAR || p.y > max.y - PILLAR
    };
    if roof_edge || pillar {
        colour
    } else {
        DVec3::new(0.08, 0.10, 0.13).lerp(HORIZON, 0.15 * ((p.z - min.z) / (max.z - min.z)))
    }
}

/// `albedo` under the sun and sky light, faded towards the horizon colour with distance.
pub(crate) fn lit(albedo: DVec3, normal: DVec3, distance: f64) -> DVec3 {
    let diffuse = normal.dot(sun_direction()).max(0.0);
    let ambient = 0.40 + 0.14 * normal.z;
    let colour = albedo * (ambient + 0.70 * diffuse);
    let haze = 1.0 - (-distance / HAZE_DISTANCE).exp();
    colour.lerp(HORIZON, haze).clamp(DVec3::ZERO, DVec3::ONE)
}

/// The sky seen along the world direction `dir` (unit): a gradient from the horizon to the zenith, a glow
/// around the sun and clouds on a virtual plane above the scene, shifted by `salt`.
pub(crate) fn sky(dir: DVec3, salt: u64) -> DVec3 {
    let up = dir.z.max(0.0);
    let mut colour = HORIZON.lerp(ZENITH, smoothstep(0.0, 1.0, (up / 0.6).min(1.0).sqrt()));
    let towards_sun = dir.dot(sun_direction()).max(0.0);
    colour += DVec3::new(1.0, 0.95, 0.8) * (0.3 * towards_sun.powi(24));
    if up > 0.0 {
        let offset = DVec2::new(hash_unit(salt, 0, 0, 0), hash_unit(salt, 1, 0, 0)) * 100.0;
        let plane = dir.truncate() / (up + 0.06) * 1.4 + offset;
        let density = fbm2(SALT_CLOUDS ^ salt, plane, 5);
        let cover = smoothstep(0.47, 0.70, density) * smoothstep(0.0, 0.10, up);
        let shade = 0.82 + 0.18 * smoothstep(0.5, 0.85, fbm2(SALT_CLOUDS ^ salt, plane * 1.7 + 3.0, 3));
        colour = colour.lerp(DVec3::splat(0.97) * shade, cover * 0.92);
    }
    colour.clamp(DVec3::ZERO, DVec3::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::street::FACADE_OFFSET;

    #[test]
    fn markings_sit_on_the_road_and_the_sky_is_structured() {
        let street = Street::new(40.0, -20.0, 100.0);
        let on_dash = ground(DVec3::new(1.0, street.centre_y, 0.0), &street);
        let between_dashes = ground(DVec3::new(5.0, street.centre_y, 0.0), &street);
        assert!(on_dash.x > 0.7 && between_dashes.x < 0.45, "{on_dash} {between_dashes}");
        let edge = ground(DVec3::new(5.0, street.y(-LANE_WIDTH), 0.0), &street);
        assert!(edge.x > 0.7);
        let beyond = ground(DVec3::new(5.0, street.y(FACADE_OFFSET + 3.0), 0.0), &street);
        assert!(beyond.x > 0.35);
        let samples: Vec<f64> =
            (0..200).map(|i| sky(DVec3::new(1.0, i as f64 * 0.02 - 2.0, 0.5).normalize(), 1).x).collect();
        let spread = samples.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - samples.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!(spread > 0.1, "clouds vary across the sky: {spread}");
    }
}
