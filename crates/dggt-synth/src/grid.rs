//! A one-dimensional grid along the street (world x) that lets a ray test only the objects near its path.
//!
//! Objects are bucketed by the x-range of their world box into cells of [`CELL_LENGTH`]; objects longer than
//! [`LONG_OBJECT`] (the ground, the sidewalks) are always tested, first. A ray walks the cells in the order it
//! crosses them and stops once its nearest hit so far lies before the cell it is leaving: any object met later
//! would be farther. The traversal order is fixed by the ray and the scene alone, so results are deterministic.

use dggt_geom::glam::DVec3;

use crate::shapes::Aabb;

/// Length of one cell along x (m).
const CELL_LENGTH: f64 = 8.0;
/// Objects at least this long along x are tested by every ray instead of being bucketed (m).
const LONG_OBJECT: f64 = 100.0;

#[derive(Debug, Clone, Default)]
pub(crate) struct StreetGrid {
    x0: f64,
    cells: Vec<Vec<u32>>,
    long: Vec<u32>,
}

impl StreetGrid {
    /// Buckets the objects with world boxes `boxes` (indexed by position).
    pub fn new(boxes: &[Aabb]) -> Self {
        let short = |b: &Aabb| b.max.x - b.min.x < LONG_OBJECT;
        let long = (0..boxes.len() as u32).filter(|&i| !short(&boxes[i as usize])).collect();
        let (x0, x1) = boxes
            .iter()
            .filter(|b| short(b))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| (lo.min(b.min.x), hi.max(b.max.x)));
        if x0 > x1 {
            return Self { x0: 0.0, cells: Vec::new(), long };
        }
        let count = ((x1 - x0) / CELL_LENGTH).floor() as usize + 1;
        let mut cells = vec![Vec::new(); count];
        for (index, b) in boxes.iter().enumerate().filter(|(_, b)| short(b)) {
            let first = ((b.min.x - x0) / CELL_LENGTH).floor().max(0.0) as usize;
            let last = (((b.max.x - x0) / CELL_LENGTH).floor() as usize).min(count - 1);
            for cell in &mut cells[first..=last] {
                cell.push(index as u32);
            }
        }
        Self { x0, cells, long }
    }

    /// Calls `visit(index)` for the objects the ray from `origin` along `dir` may hit, nearest cells first.
    /// `visit` tests the object and returns the distance of the nearest hit found so far (infinity if none).
    pub fn traverse(&self, origin: DVec3, dir: DVec3, mut visit: impl FnMut(u32) -> f64) {
        let mut best = f64::INFINITY;
        for &index in &self.long {
            best = visit(index);
        }
        let count = self.cells.len() as i64;
        if count == 0 {
            return;
        }
        let cell_of = |x: f64| ((x - self.x0) / CELL_LENGTH).floor() as i64;
        if dir.x == 0.0 {
            let cell = cell_of(origin.x);
            if (0..count).contains(&cell) {
                for &index in &self.cells[cell as usize] {
                    visit(index);
                }
            }
            return;
        }
        let x_end = self.x0 + count as f64 * CELL_LENGTH;
        let (ta, tb) = ((self.x0 - origin.x) / dir.x, (x_end - origin.x) / dir.x);
        let (t_in, t_out) = (ta.min(tb).max(0.0), ta.max(tb));
        if t_in > t_out || t_in >= best {
            return;
        }
        let step = if dir.x > 0.0 { 1 } else { -1 };
        let mut cell = cell_of(origin.x + dir.x * t_in).clamp(0, count - 1);
        loop {
            for &index in &self.cells[cell as usize] {
                best = visit(index);
            }
            let boundary = self.x0 + (if step > 0 { cell + 1 } else { cell }) as f64 * CELL_LENGTH;
            if best <= (boundary - origin.x) / dir.x {
                return;
            }
            cell += step;
            if !(0..count).contains(&cell) {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visits_every_object_a_ray_crosses() {
        let boxes: Vec<Aabb> = (0..40)
            .map(|i| {
                let x = i as f64 * 5.0 - 60.0;
                Aabb::new(DVec3::new(x, 3.0, 0.0), DVec3::new(x + 4.0, 5.0, 2.0))
            })
            .chain([Aabb::new(DVec3::splat(-1e6), DVec3::new(1e6, 1e6, 0.0))])
            .collect();
        let grid = StreetGrid::new(&boxes);
        for (origin, dir) in [
            (DVec3::new(0.0, 0.0, 1.0), DVec3::new(1.0, 0.3, 0.0).normalize()),
            (DVec3::new(0.0, 0.0, 1.0), DVec3::new(-1.0, 0.05, 0.0).normalize()),
            (DVec3::new(-200.0, 4.0, 1.0), DVec3::X),
            (DVec3::new(3.0, 0.0, 1.0), DVec3::Y),
        ] {
            let mut visited = std::collections::BTreeSet::new();
            grid.traverse(origin, dir, |i| {
                visited.insert(i);
                f64::INFINITY
            });
            for (i, b) in boxes.iter().enumerate() {
                if b.interval(origin, dir).is_some_and(|(_, exit, _)| exit > 0.0) {
                    assert!(visited.contains(&(i as u32)), "box {i} missed for {origin} {dir}");
                }
            }
        }
    }
}
