//! The ground flag of the export's lidar rows: a plane fitted to the lowest points and refined.
//!
//! Seeds are the points less than 1.2 m above the mean height of the 20 lowest; a plane `z = a x + b y + c`
//! is fitted by least squares, then refitted 10 times to the points whose signed distance above it is below
//! 0.3 m. Those points are ground (flag 1.0, else 0.0). Heights are the vehicle frame's z (up).

use dggt_geom::glam::{DMat3, DVec3};

use super::lidar::{GROUND_COLUMN, LidarRow};

const LOWEST_POINTS: usize = 20;
const SEED_HEIGHT_M: f64 = 1.2;
const ITERATIONS: usize = 10;
const GROUND_DISTANCE_M: f64 = 0.3;

/// Sets the ground column of every row.
pub fn mark_ground(rows: &mut [LidarRow]) {
    let points: Vec<DVec3> = rows.iter().map(|r| DVec3::new(r[3] as f64, r[4] as f64, r[5] as f64)).collect();
    let flags = ground_flags(&points);
    for (row, ground) in rows.iter_mut().zip(flags) {
        row[GROUND_COLUMN] = if ground { 1.0 } else { 0.0 };
    }
}

fn ground_flags(points: &[DVec3]) -> Vec<bool> {
    if points.len() < 3 {
        return vec![false; points.len()];
    }
    let mut heights: Vec<f64> = points.iter().map(|p| p.z).collect();
    let lowest = LOWEST_POINTS.min(heights.len());
    heights.select_nth_unstable_by(lowest - 1, f64::total_cmp);
    let seed_limit = heights[..lowest].iter().sum::<f64>() / lowest as f64 + SEED_HEIGHT_M;
    let mut ground: Vec<bool> = points.iter().map(|p| p.z < seed_limit).collect();
    for _ in 0..ITERATIONS {
        let Some(plane) = fit_plane(points.iter().zip(&ground).filter(|(_, g)| **g).map(|(p, _)| *p)) else { break };
        ground = points.iter().map(|p| plane.signed_distance(*p) < GROUND_DISTANCE_M).collect();
    }
    ground
}

/// `z = a x + b y + c`.
#[derive(Debug, Clone, Copy)]
struct Plane {
    a: f64,
    b: f64,
    c: f64,
}

impl Plane {
    fn signed_distance(&self, p: DVec3) -> f64 {
        (p.z - self.a * p.x - self.b * p.y - self.c) / (self.a * self.a + self.b * self.b + 1.0).sqrt()
    }
}

/// Least squares on the normal equations; `None` when the points do not determine a plane.
fn fit_plane(points: impl Iterator<Item = DVec3>) -> Option<Plane> {
    let (mut normal, mut rhs) = (DMat3::ZERO, DVec3::ZERO);
    for p in points {
        let row = DVec3::new(p.x, p.y, 1.0);
        normal += DMat3::from_cols(row * row.x, row * row.y, row * row.z);
        rhs += row * p.z;
    }
    if normal.determinant().abs() < 1e-9 {
        return None;
    }
    let solution = normal.inverse() * rhs;
    Some(Plane { a: solution.x, b: solution.y, c: solution.z }).filter(|_| solution.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sloped_road_is_ground_and_what_stands_on_it_is_not() {
        let mut points = Vec::new();
        for i in 0..30 {
            for j in 0..30 {
                let (x, y) = (i as f64, j as f64 - 15.0);
                points.push(DVec3::new(x, y, -2.0 + 0.05 * x));
            }
        }
        let road = points.len();
        for k in 0..50 {
            points.push(DVec3::new(10.0, 3.0, -1.5 + 0.05 * 10.0 + k as f64 * 0.05));
        }
        let flags = ground_flags(&points);
        assert!(flags[..road].iter().all(|g| *g), "every road point is ground");
        let standing = flags[road..].iter().filter(|g| **g).count();
        // The pole starts 0.5 m above the road: none of it is within 0.3 m.
        assert_eq!(standing, 0);
    }
}
