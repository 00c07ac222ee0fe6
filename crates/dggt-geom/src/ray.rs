//! Where a ray crosses a box: the slab test, for boxes given in their own axes (centred at the origin, faces
//! perpendicular to the axes), so that callers turn the ray into the box's frame first.

use glam::DVec3;

/// The ray parameters `(entry, exit)` between which `origin + s · direction` lies inside the box of half extents
/// `half` centred at the origin (faces included), or `None` when the line misses the box. `entry` may be negative
/// (the box lies partly behind the origin, or holds it); the caller decides which part of the line counts.
pub fn ray_box_interval(origin: DVec3, direction: DVec3, half: DVec3) -> Option<(f64, f64)> {
    let (mut entry, mut exit) = (f64::NEG_INFINITY, f64::INFINITY);
    for axis in 0..3 {
        let (o, d, h) = (origin[axis], direction[axis], half[axis]);
        if d.abs() < 1e-12 {
            if o.abs() > h {
                return None;
            }
            continue;
        }
        let (a, b) = ((-h - o) / d, (h - o) / d);
        entry = entry.max(a.min(b));
        exit = exit.min(a.max(b));
    }
    (entry <= exit).then_some((entry, exit))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ray_through_a_box_enters_and_leaves_at_its_faces() {
        let half = DVec3::new(2.0, 1.0, 0.5);
        let hit = ray_box_interval(DVec3::new(-10.0, 0.0, 0.0), DVec3::X, half).unwrap();
        assert_eq!(hit, (8.0, 12.0));
        let from_inside = ray_box_interval(DVec3::ZERO, DVec3::Y, half).unwrap();
        assert_eq!(from_inside, (-1.0, 1.0));
        assert!(ray_box_interval(DVec3::new(-10.0, 2.0, 0.0), DVec3::X, half).is_none(), "passes beside it");
        let diagonal = DVec3::new(1.0, 1.0, 0.0).normalize();
        assert!(ray_box_interval(DVec3::new(-10.0, -8.5, 0.0), diagonal, half).is_some(), "clips a corner");
    }
}
