//! Ray intersection with the primitives scenes are built from: axis-aligned boxes, vertical cylinders and spheres.
//!
//! Primitives live in the frame of the object that owns them; the caller transforms the ray into that frame.
//! Intersections report the entry distance along the ray and the outward unit normal. A ray that starts inside
//! a primitive does not hit it (cameras never sit inside scene geometry).

use dggt_geom::Rigid;
use dggt_geom::glam::{DVec2, DVec3};

/// Closest accepted hit distance: hits nearer than this are treated as the surface the ray starts on.
pub(crate) const T_MIN: f64 = 1e-6;

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: DVec3,
    pub max: DVec3,
}

impl Aabb {
    /// The box spanned by two opposite corners, in any order.
    pub fn new(a: DVec3, b: DVec3) -> Self {
        Self { min: a.min(b), max: a.max(b) }
    }

    /// A box of `size` centred on `centre`.
    pub fn centred(centre: DVec3, size: DVec3) -> Self {
        Self::new(centre - size * 0.5, centre + size * 0.5)
    }

    pub fn union(&self, other: &Self) -> Self {
        Self { min: self.min.min(other.min), max: self.max.max(other.max) }
    }

    pub fn size(&self) -> DVec3 {
        self.max - self.min
    }

    pub fn corners(&self) -> [DVec3; 8] {
        std::array::from_fn(|i| {
            DVec3::new(
                if i & 1 == 0 { self.min.x } else { self.max.x },
                if i & 2 == 0 { self.min.y } else { self.max.y },
                if i & 4 == 0 { self.min.z } else { self.max.z },
            )
        })
    }

    pub fn contains(&self, p: DVec3, slack: f64) -> bool {
        p.cmpge(self.min - slack).all() && p.cmple(self.max + slack).all()
    }

    /// The world box enclosing this box after a rigid transform.
    pub fn transformed<To, From>(&self, transform: &Rigid<To, From>) -> Self {
        let corners = self.corners().map(|c| transform.transform_point(c));
        corners[1..].iter().fold(Self::new(corners[0], corners[0]), |b, &c| b.union(&Self::new(c, c)))
    }

    /// The parameter interval `(entry, exit)` over which the line `origin + t dir` lies inside the box, and the
    /// axis of the entry face; `None` when the line misses.
    pub fn interval(&self, origin: DVec3, dir: DVec3) -> Option<(f64, f64, usize)> {
        let (mut entry, mut exit, mut axis) = (f64::NEG_INFINITY, f64::INFINITY, 0);
        for i in 0..3 {
            let (o, d, lo, hi) = (origin[i], dir[i], self.min[i], self.max[i]);
            if d == 0.0 {
                if o < lo || o > hi {
                    return None;
                }
                continue;
            }
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            let (near, far) = if a <= b { (a, b) } else { (b, a) };
            if near > entry {
                entry = near;
                axis = i;
            }
            exit = exit.min(far);
            if entry > exit {
                return None;
            }
        }
        Some((entry, exit, axis))
    }

    /// The entry hit `(t, outward normal)` with `T_MIN < t < t_max`.
    pub fn hit(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<(f64, DVec3)> {
        let (entry, _, axis) = self.interval(origin, dir)?;
        if entry <= T_MIN || entry >= t_max {
            return None;
        }
        let mut normal = DVec3::ZERO;
        normal[axis] = if dir[axis] > 0.0 { -1.0 } else { 1.0 };
        Some((entry, normal))
    }
}

/// A cylinder with a vertical (+z) axis through `centre`, capped at `z_min` and `z_max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinder {
    pub centre: DVec2,
    pub radius: f64,
    pub z_min: f64,
    pub z_max: f64,
}

impl Cylinder {
    pub fn bounds(&self) -> Aabb {
        let r = DVec2::splat(self.radius);
        Aabb::new((self.centre - r).extend(self.z_min), (self.centre + r).extend(self.z_max))
    }

    pub fn hit(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<(f64, DVec3)> {
        let mut best: Option<(f64, DVec3)> = None;
        let mut best_t = t_max;
        let (ox, oy) = (origin.x - self.centre.x, origin.y - self.centre.y);
        let a = dir.x * dir.x + dir.y * dir.y;
        if a > 1e-18 {
            let b = ox * dir.x + oy * dir.y;
            let c = ox * ox + oy * oy - self.radius * self.radius;
            let discriminant = b * b - a * c;
            if discriminant >= 0.0 {
                // Only the entry root: the exit root is the inside of the wall.
                let t = (-b - discriminant.sqrt()) / a;
                let z = origin.z + t * dir.z;
                if t > T_MIN && t < best_t && z >= self.z_min && z <= self.z_max {
                    let normal = DVec3::new(ox + t * dir.x, oy + t * dir.y, 0.0) / self.radius;
                    best = Some((t, normal));
                    best_t = t;
                }
            }
        }
        if dir.z != 0.0 {
            for (z, nz) in [(self.z_max, 1.0), (self.z_min, -1.0)] {
                let t = (z - origin.z) / dir.z;
                let (px, py) = (ox + t * dir.x, oy + t * dir.y);
                if t > T_MIN && t < best_t && px * px + py * py <= self.radius * self.radius {
                    best = Some((t, DVec3::new(0.0, 0.0, nz)));
                    best_t = t;
                }
            }
        }
        best
    }
}

/// A sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    pub centre: DVec3,
    pub radius: f64,
}

impl Sphere {
    pub fn bounds(&self) -> Aabb {
        Aabb::centred(self.centre, DVec3::splat(2.0 * self.radius))
    }

    pub fn hit(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<(f64, DVec3)> {
        let oc = origin - self.centre;
        let a = dir.length_squared();
        let b = oc.dot(dir);
        let c = oc.length_squared() - self.radius * self.radius;
        let discriminant = b * b - a * c;
        if discriminant < 0.0 {
            return None;
        }
        let t = (-b - discriminant.sqrt()) / a;
        (t > T_MIN && t < t_max).then(|| (t, (oc + dir * t) / self.radius))
    }
}

/// One primitive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    Box(Aabb),
    Cylinder(Cylinder),
    Sphere(Sphere),
}

impl Shape {
    pub fn bounds(&self) -> Aabb {
        match self {
            Shape::Box(b) => *b,
            Shape::Cylinder(c) => c.bounds(),
            Shape::Sphere(s) => s.bounds(),
        }
    }

    /// The nearest hit `(t, outward normal)` with `T_MIN < t < t_max`.
    pub fn hit(&self, origin: DVec3, dir: DVec3, t_max: f64) -> Option<(f64, DVec3)> {
        match self {
            Shape::Box(b) => b.hit(origin, dir, t_max),
            Shape::Cylinder(c) => c.hit(origin, dir, t_max),
            Shape::Sphere(s) => s.hit(origin, dir, t_max),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_hits_report_entry_face_and_miss_from_inside() {
        let b = Aabb::new(DVec3::new(1.0, -1.0, -1.0), DVec3::new(3.0, 1.0, 1.0));
        let (t, n) = b.hit(DVec3::ZERO, DVec3::X, f64::INFINITY).unwrap();
        assert_eq!((t, n), (1.0, -DVec3::X));
        assert!(b.hit(DVec3::new(2.0, 0.0, 0.0), DVec3::X, f64::INFINITY).is_none());
        assert!(b.hit(DVec3::ZERO, -DVec3::X, f64::INFINITY).is_none());
        assert!(b.hit(DVec3::new(0.0, 5.0, 0.0), DVec3::X, f64::INFINITY).is_none());
        assert!(b.hit(DVec3::ZERO, DVec3::X, 0.5).is_none());
    }

    #[test]
    fn cylinder_side_and_cap_and_sphere() {
        let c = Cylinder { centre: DVec2::new(5.0, 0.0), radius: 0.5, z_min: 0.0, z_max: 2.0 };
        let (t, n) = c.hit(DVec3::new(0.0, 0.0, 1.0), DVec3::X, f64::INFINITY).unwrap();
        assert!((t - 4.5).abs() < 1e-12 && n.abs_diff_eq(-DVec3::X, 1e-12));
        let (t, n) = c.hit(DVec3::new(5.0, 0.1, 4.0), -DVec3::Z, f64::INFINITY).unwrap();
        assert!((t - 2.0).abs() < 1e-12 && n == DVec3::Z);
        assert!(c.hit(DVec3::new(0.0, 0.0, 2.5), DVec3::X, f64::INFINITY).is_none());
        let s = Sphere { centre: DVec3::new(0.0, 0.0, 10.0), radius: 2.0 };
        let (t, n) = s.hit(DVec3::ZERO, DVec3::Z, f64::INFINITY).unwrap();
        assert!((t - 8.0).abs() < 1e-12 && n.abs_diff_eq(-DVec3::Z, 1e-12));
    }
}
