//! Dynamic masks (`dynamic_masks/{all,human,vehicle}/`, 255 = dynamic): annotated boxes projected into a camera,
//! per class. `all` is `human` ∪ `vehicle`. Which boxes are drawn is a [`MaskRule`], how is a [`MaskShape`]; a
//! [`DynamicMaskStyle`] picks both for a conversion.
//!
//! - [`MaskShape::Rectangle`] (drivestudio's): a box is drawn only when all 8 corners project inside the image in
//!   front of the camera; its rectangle covers rows `floor(v_min) .. floor(v_min) + floor(v_max - v_min)` (end
//!   exclusive) and the same for columns.
//! - [`MaskShape::Outline`]: the box's silhouette, the convex hull of its projected edges after cutting away what
//!   lies behind [`NEAR_PLANE_M`] in front of the camera, filled where a pixel's centre lies inside, clipped to the
//!   image, so that a car crossing the image border or passing beside the camera keeps its visible part. Edges
//!   are sampled so that lens distortion bends them (the hull of the samples).

use dggt_data::{DynamicMaskKind, ExportLayout, images, io};
use dggt_geom::glam::{DVec2, DVec3};
use image::{GrayImage, Luma};

use crate::boxes::{AnnotatedBox, ObjectClass};
use crate::camera::EgoCamera;
use crate::error::Result;

/// How far in front of the camera a box's outline is cut (m).
pub const NEAR_PLANE_M: f64 = 0.05;

/// Which boxes a dataset's masks show.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MaskRule {
    /// drivestudio's Waymo rule: boxes the lidar saw, moving faster than this horizontal speed (m/s).
    SeenAndFasterThan(f64),
    /// drivestudio's nuScenes and Argoverse 2 rule: every box of a masked class, parked cars included.
    EveryBox,
    /// Boxes whose object moves faster than this horizontal speed (m/s) at the view's time.
    FasterThan(f64),
}

impl MaskRule {
    fn draws(self, object: &AnnotatedBox) -> bool {
        match self {
            Self::SeenAndFasterThan(speed) => object.has_points && object.speed > speed,
            Self::EveryBox => true,
            Self::FasterThan(speed) => object.speed > speed,
        }
    }
}

/// How a drawn box fills the mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskShape {
    /// drivestudio's: the axis-aligned rectangle around the projected corners, only when all 8 are inside.
    Rectangle,
    /// The box's projected outline, clipped to the image.
    Outline,
}

/// What dynamic masks a conversion writes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DynamicMaskStyle {
    /// The objects that move at the view's time, faster than `min_speed_m_s` (from their tracks, or Waymo's
    /// own speeds), each as its projected outline.
    MovingOutlines { min_speed_m_s: f64 },
    /// The release's data exactly: the dataset's drivestudio rule, rectangles.
    Drivestudio,
}

impl Default for DynamicMaskStyle {
    fn default() -> Self {
        Self::MovingOutlines { min_speed_m_s: crate::tracks::DEFAULT_MOVING_SPEED_M_S }
    }
}

impl DynamicMaskStyle {
    /// The rule and shape for a dataset whose drivestudio rule is `drivestudio`.
    pub fn rule_and_shape(self, drivestudio: MaskRule) -> (MaskRule, MaskShape) {
        match self {
            Self::MovingOutlines { min_speed_m_s } => (MaskRule::FasterThan(min_speed_m_s), MaskShape::Outline),
            Self::Drivestudio => (drivestudio, MaskShape::Rectangle),
        }
    }

    /// `moving-outlines (> 0.5 m/s)` or `drivestudio`: what a done marker and `dynamic_masks/SOURCE.txt` record.
    pub fn describe(self) -> String {
        match self {
            Self::MovingOutlines { min_speed_m_s } => format!("moving-outlines (> {min_speed_m_s} m/s)"),
            Self::Drivestudio => "drivestudio".into(),
        }
    }

    /// Writes [`Self::note`] to `dynamic_masks/SOURCE.txt`.
    pub fn write_note(self, layout: &ExportLayout) -> Result<()> {
        io::write_atomically(&layout.root().join("dynamic_masks/SOURCE.txt"), self.note().as_bytes())?;
        Ok(())
    }

    /// The note `dynamic_masks/SOURCE.txt` holds.
    pub fn note(self) -> String {
        match self {
            Self::MovingOutlines { min_speed_m_s } => format!(
                "Dynamic masks: {}.\nEach object whose box moves faster than {min_speed_m_s} m/s at the view's time \
                 (its track's horizontal displacement over {} s, or the dataset's own speed where it has one), \
                 drawn as the projected outline of its 3D box (the convex hull of its silhouette, clipped to the \
                 image), with the box placed at the camera's own time. Parked and stopped objects are static. \
                 Approximate: an outline covers what the box covers, including what a nearer object hides.\n",
                self.describe(),
                crate::tracks::SPEED_WINDOW_S,
            ),
            Self::Drivestudio => "Dynamic masks: drivestudio.\nThe release's rule: axis-aligned rectangles around \
                 projected boxes whose 8 corners are all inside the image (every box of a masked class for \
                 nuScenes and Argoverse 2, parked ones included; boxes the lidar saw moving faster than 1 m/s for \
                 Waymo).\n"
                .into(),
        }
    }
}

/// One view's three masks (255 = dynamic).
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicMasks {
    pub all: GrayImage,
    pub human: GrayImage,
    pub vehicle: GrayImage,
}

impl DynamicMasks {
    /// Draws the boxes that `rule` keeps into `camera`, each as `shape`.
    pub fn draw(camera: &EgoCamera, boxes: &[AnnotatedBox], rule: MaskRule, shape: MaskShape) -> Self {
        let (width, height) = (camera.size.width, camera.size.height);
        let mut masks = Self {
            all: GrayImage::new(width, height),
            human: GrayImage::new(width, height),
            vehicle: GrayImage::new(width, height),
        };
        match shape {
            MaskShape::Rectangle => {
                for object in boxes.iter().filter(|object| rule.draws(object)) {
                    let Some((min, max)) = projected_bounds(camera, object) else { continue };
                    fill_rectangle(masks.of_class(object.class), min, max);
                    fill_rectangle(&mut masks.all, min, max);
                }
            }
            MaskShape::Outline => masks.draw_outlines(camera, boxes, rule),
        }
        masks
    }

    fn of_class(&mut self, class: ObjectClass) -> &mut GrayImage {
        match class {
            ObjectClass::Vehicle => &mut self.vehicle,
            ObjectClass::Human => &mut self.human,
        }
    }

    /// Every box's outline, the farthest first (by its centre's distance from the camera): a box `rule` draws
    /// sets its pixels, any other (a parked car) clears them, so that a still object in front of a moving one
    /// hides it as it does in the image.
    fn draw_outlines(&mut self, camera: &EgoCamera, boxes: &[AnnotatedBox], rule: MaskRule) {
        for object in farthest_first(camera, boxes) {
            let outline = projected_outline(camera, object);
            let value = if rule.draws(object) { 255 } else { 0 };
            if value == 255 {
                fill_convex(self.of_class(object.class), &outline, value);
            } else {
                fill_convex(&mut self.vehicle, &outline, value);
                fill_convex(&mut self.human, &outline, value);
            }
            fill_convex(&mut self.all, &outline, value);
        }
    }

    /// Writes the three masks of view (`frame`, `camera`).
    pub fn write(&self, layout: &ExportLayout, frame: usize, camera: usize) -> Result<()> {
        for (kind, mask) in [
            (DynamicMaskKind::All, &self.all),
            (DynamicMaskKind::Human, &self.human),
            (DynamicMaskKind::Vehicle, &self.vehicle),
        ] {
            images::write_png_gray(&layout.dynamic_mask(kind, frame, camera), mask)?;
        }
        Ok(())
    }
}

/// The boxes in drawing order: the farthest first, by their centre's distance from the camera, so that what is
/// drawn later (nearer) covers what it hides.
pub fn farthest_first<'a>(camera: &EgoCamera, boxes: &'a [AnnotatedBox]) -> Vec<&'a AnnotatedBox> {
    let distance =
        |object: &AnnotatedBox| camera.camera_from_ego.transform_point(object.ego_from_box.translation()).length();
    let mut by_distance: Vec<(f64, &AnnotatedBox)> = boxes.iter().map(|b| (distance(b), b)).collect();
    by_distance.sort_by(|a, b| b.0.total_cmp(&a.0));
    by_distance.into_iter().map(|(_, object)| object).collect()
}

/// The image-space bounding rectangle of a box, when every corner projects inside the image.
fn projected_bounds(camera: &EgoCamera, object: &AnnotatedBox) -> Option<(DVec2, DVec2)> {
    let mut min = DVec2::INFINITY;
    let mut max = DVec2::NEG_INFINITY;
    for corner in object.corners_in_ego() {
        let pixel = camera.project_inside(corner)?;
        min = min.min(pixel);
        max = max.max(pixel);
    }
    Some((min, max))
}

/// Samples along each box edge: enough for a distorted edge's bend to show in the hull.
const EDGE_SAMPLES: usize = 8;

/// The convex hull (counter-clockwise in pixel coordinates) of a box's projection: its 12 edges cut at
/// [`NEAR_PLANE_M`] in front of the camera, sampled and projected. Empty when the box lies wholly behind.
pub fn projected_outline(camera: &EgoCamera, object: &AnnotatedBox) -> Vec<DVec2> {
    let corners = object.corners_in_ego().map(|c| camera.camera_from_ego.transform_point(c));
    let mut pixels = Vec::with_capacity(12 * (EDGE_SAMPLES + 1));
    for (a, b) in box_edges().map(|(i, j)| (corners[i], corners[j])) {
        let Some((a, b)) = clip_to_near_plane(a, b) else { continue };
        for k in 0..=EDGE_SAMPLES {
            let point = a.lerp(b, k as f64 / EDGE_SAMPLES as f64);
            pixels.extend(camera.project_camera_point(point));
        }
    }
    convex_hull(pixels)
}

/// The 12 edges of a box as pairs of corner indices ([`AnnotatedBox::corners_in_ego`]: bit 0 = x, 1 = y, 2 = z).
fn box_edges() -> impl Iterator<Item = (usize, usize)> {
    (0..8).flat_map(|i| (0..3).map(move |bit| (i, i ^ (1 << bit)))).filter(|(i, j)| i < j)
}

/// The part of segment `a`-`b` (camera frame) at depth `NEAR_PLANE_M` or more.
fn clip_to_near_plane(a: DVec3, b: DVec3) -> Option<(DVec3, DVec3)> {
    match (a.z >= NEAR_PLANE_M, b.z >= NEAR_PLANE_M) {
        (true, true) => Some((a, b)),
        (false, false) => None,
        (a_in, _) => {
            let cut = a.lerp(b, (NEAR_PLANE_M - a.z) / (b.z - a.z));
            Some(if a_in { (a, cut) } else { (cut, b) })
        }
    }
}

/// Andrew's monotone chain: the hull's vertices counter-clockwise (in a y-down image: clockwise on screen).
fn convex_hull(mut points: Vec<DVec2>) -> Vec<DVec2> {
    points.retain(|p| p.is_finite());
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<DVec2> = Vec::with_capacity(points.len() * 2);
    for pass in [points.clone(), points.into_iter().rev().collect()] {
        let start = hull.len();
        for p in pass {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// Sets to `value` every pixel whose centre lies inside the convex polygon (edges included).
pub fn fill_convex(mask: &mut GrayImage, polygon: &[DVec2], value: u8) {
    for_each_pixel_inside(polygon, mask.width(), mask.height(), |col, row| mask.put_pixel(col, row, Luma([value])));
}

/// Calls `visit(col, row)` for every pixel of a `width` x `height` image whose centre lies inside the convex
/// polygon: per row, the span between the polygon's crossings of the row's centre line.
pub fn for_each_pixel_inside(polygon: &[DVec2], width: u32, height: u32, mut visit: impl FnMut(u32, u32)) {
    if polygon.len() < 3 {
        return;
    }
    let (low, high) = polygon.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p.y), hi.max(p.y)));
    let first_row = (low - 0.5).ceil().max(0.0) as u32;
    let end_row = ((high - 0.5).floor() + 1.0).clamp(0.0, height as f64) as u32;
    for row in first_row..end_row {
        let y = row as f64 + 0.5;
        let (mut left, mut right) = (f64::INFINITY, f64::NEG_INFINITY);
        for (a, b) in polygon.iter().zip(polygon.iter().cycle().skip(1)) {
            if (a.y - y) * (b.y - y) > 0.0 || a.y == b.y && a.y != y {
                continue;
            }
            let xs = if a.y == b.y { [a.x, b.x] } else { [a.x + (b.x - a.x) * (y - a.y) / (b.y - a.y); 2] };
            left = left.min(xs[0].min(xs[1]));
            right = right.max(xs[0].max(xs[1]));
        }
        let first_col = (left - 0.5).ceil().max(0.0);
        let end_col = ((right - 0.5).floor() + 1.0).min(width as f64);
        for col in first_col as u32..end_col.max(first_col) as u32 {
            visit(col, row);
        }
    }
}

fn fill_rectangle(mask: &mut GrayImage, min: DVec2, max: DVec2) {
    let extent = max - min;
    let (col0, row0) = (min.x as u32, min.y as u32);
    let cols = col0..(col0 + extent.x as u32).min(mask.width());
    let rows = row0..(row0 + extent.y as u32).min(mask.height());
    for row in rows {
        for col in cols.clone() {
            mask.put_pixel(col, row, Luma([255]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boxes::ObjectBox;
    use crate::camera::Distortion;
    use dggt_geom::glam::DVec3;
    use dggt_geom::{ImageSize, PinholeIntrinsics, Rigid};

    fn camera() -> EgoCamera {
        EgoCamera {
            intrinsics: PinholeIntrinsics::new(100.0, 100.0, 50.0, 40.0).unwrap(),
            distortion: Distortion::default(),
            camera_from_ego: dggt_geom::axes::ego_from_opencv_camera(&Rigid::IDENTITY).inverse(),
            size: ImageSize::new(100, 80).unwrap(),
        }
    }

    fn object(class: ObjectClass, centre: DVec3, speed: f64) -> AnnotatedBox {
        AnnotatedBox {
            id: "x".into(),
            class_name: "test",
            class,
            ego_from_box: Rigid::<dggt_geom::Ego, ObjectBox>::from_rotation_translation(Default::default(), centre)
                .unwrap(),
            size: DVec3::new(2.0, 2.0, 2.0),
            speed,
            has_points: true,
        }
    }

    #[test]
    fn moving_boxes_fill_their_rectangle_in_their_class_only() {
        let walker = object(ObjectClass::Human, DVec3::new(10.0, 0.0, 0.0), 1.5);
        let masks = DynamicMasks::draw(&camera(), &[walker], MaskRule::SeenAndFasterThan(1.0), MaskShape::Rectangle);
        // Corners at depth 9 and 11: u in [50 - 100/9, 50 + 100/9] = [38.89, 61.11], v likewise around 40.
        let set: Vec<(u32, u32)> =
            masks.human.enumerate_pixels().filter(|p| p.2.0[0] == 255).map(|p| (p.0, p.1)).collect();
        let (cols, rows): (Vec<u32>, Vec<u32>) = set.iter().copied().unzip();
        assert_eq!((*cols.iter().min().unwrap(), *cols.iter().max().unwrap()), (38, 59));
        assert_eq!((*rows.iter().min().unwrap(), *rows.iter().max().unwrap()), (28, 49));
        assert_eq!(set.len(), 22 * 22);
        assert_eq!(masks.all, masks.human);
        assert!(masks.vehicle.pixels().all(|p| p.0[0] == 0));
    }

    #[test]
    fn slow_unseen_and_partly_visible_boxes_are_not_drawn() {
        let slow = object(ObjectClass::Vehicle, DVec3::new(10.0, 0.0, 0.0), 0.9);
        let mut unseen = object(ObjectClass::Vehicle, DVec3::new(10.0, 0.0, 0.0), 5.0);
        unseen.has_points = false;
        let at_the_edge = object(ObjectClass::Vehicle, DVec3::new(10.0, 4.5, 0.0), 5.0);
        let boxes = [slow, unseen, at_the_edge];
        let masks = DynamicMasks::draw(&camera(), &boxes, MaskRule::SeenAndFasterThan(1.0), MaskShape::Rectangle);
        assert!(masks.all.pixels().all(|p| p.0[0] == 0));
        let every = DynamicMasks::draw(&camera(), &boxes, MaskRule::EveryBox, MaskShape::Rectangle);
        assert!(every.vehicle.pixels().any(|p| p.0[0] == 255), "without the speed rule the centred boxes are drawn");
    }

    fn set_pixels(mask: &GrayImage) -> Vec<(u32, u32)> {
        mask.enumerate_pixels().filter(|p| p.2.0[0] == 255).map(|p| (p.0, p.1)).collect()
    }

    #[test]
    fn an_outline_of_a_box_facing_the_camera_is_its_front_face_grown_by_the_back_one() {
        // Axis-aligned 2 m cube at depth 10: its projection is the near face's square, [38.89, 61.11] x
        // [28.89, 51.11]; the hull fills the same pixels as the rectangle rule.
        let cube = object(ObjectClass::Vehicle, DVec3::new(10.0, 0.0, 0.0), 5.0);
        let outline =
            DynamicMasks::draw(&camera(), std::slice::from_ref(&cube), MaskRule::FasterThan(1.0), MaskShape::Outline);
        let pixels = set_pixels(&outline.vehicle);
        let (cols, rows): (Vec<u32>, Vec<u32>) = pixels.iter().copied().unzip();
        assert_eq!((*cols.iter().min().unwrap(), *cols.iter().max().unwrap()), (39, 60));
        assert_eq!((*rows.iter().min().unwrap(), *rows.iter().max().unwrap()), (29, 50));
        assert_eq!(pixels.len(), 22 * 22);
        let slow = DynamicMasks::draw(&camera(), &[cube], MaskRule::FasterThan(5.0), MaskShape::Outline);
        assert!(set_pixels(&slow.all).is_empty(), "no faster than the threshold: static");
    }

    #[test]
    fn a_turned_box_fills_its_hull_not_its_rectangle() {
        let mut turned = object(ObjectClass::Vehicle, DVec3::new(10.0, 0.0, 0.0), 5.0);
        let tilt = dggt_geom::glam::DQuat::from_rotation_x(std::f64::consts::FRAC_PI_4);
        turned.ego_from_box = Rigid::from_rotation_translation(tilt, DVec3::new(10.0, 0.0, 0.0)).unwrap();
        let outline =
            DynamicMasks::draw(&camera(), std::slice::from_ref(&turned), MaskRule::EveryBox, MaskShape::Outline);
        let rectangle = DynamicMasks::draw(&camera(), &[turned], MaskRule::EveryBox, MaskShape::Rectangle);
        let (inside, around) = (set_pixels(&outline.all), set_pixels(&rectangle.all));
        // Rolled 45 degrees about the viewing axis the silhouette is a diamond (an octagon with the back face):
        // its corners of the rectangle stay empty, its centre is filled.
        assert!(inside.contains(&(50, 40)));
        assert!(!inside.contains(&(36, 26)) && around.contains(&(36, 26)), "a corner of the rectangle");
        assert!(inside.len() < around.len() * 9 / 10, "{} of {}", inside.len(), around.len());
    }

    #[test]
    fn a_box_crossing_the_image_border_or_beside_the_camera_keeps_its_visible_part() {
        // Half out on the left: the rectangle rule draws nothing, the outline the part inside.
        let at_the_edge = object(ObjectClass::Vehicle, DVec3::new(10.0, 5.0, 0.0), 5.0);
        let boxes = [at_the_edge];
        assert!(
            set_pixels(&DynamicMasks::draw(&camera(), &boxes, MaskRule::EveryBox, MaskShape::Rectangle).all).is_empty()
        );
        let outline = set_pixels(&DynamicMasks::draw(&camera(), &boxes, MaskRule::EveryBox, MaskShape::Outline).all);
        assert!(outline.contains(&(0, 40)) && outline.iter().all(|&(col, _)| col < 14), "{outline:?}");
        // A long truck reaching from behind the camera to 10 m ahead, 3 m to the left: its near part is cut at
        // the near plane, and what is ahead fills the left of the image down to the bottom edge.
        let mut truck = object(ObjectClass::Vehicle, DVec3::new(2.0, 3.0, -0.5), 5.0);
        truck.size = DVec3::new(16.0, 2.0, 3.0);
        let pixels = set_pixels(&DynamicMasks::draw(&camera(), &[truck], MaskRule::EveryBox, MaskShape::Outline).all);
        assert!(pixels.contains(&(0, 79)) && pixels.contains(&(25, 40)), "{} pixels", pixels.len());
        assert!(!pixels.contains(&(99, 40)));
    }

    #[test]
    fn a_box_wholly_behind_the_camera_draws_nothing() {
        let behind = object(ObjectClass::Human, DVec3::new(-5.0, 0.0, 0.0), 5.0);
        let masks = DynamicMasks::draw(&camera(), &[behind], MaskRule::EveryBox, MaskShape::Outline);
        assert!(set_pixels(&masks.all).is_empty());
    }

    #[test]
    fn pixel_centres_decide_what_a_polygon_covers() {
        let square = [DVec2::new(1.0, 1.0), DVec2::new(3.0, 1.0), DVec2::new(3.0, 3.0), DVec2::new(1.0, 3.0)];
        let mut covered = Vec::new();
        for_each_pixel_inside(&square, 5, 5, |col, row| covered.push((col, row)));
        assert_eq!(covered, vec![(1, 1), (2, 1), (1, 2), (2, 2)]);
        let huge = [DVec2::new(-1e12, -1e12), DVec2::new(1e12, -1e12), DVec2::new(0.0, 1e12)];
        let mut count = 0;
        for_each_pixel_inside(&huge, 4, 3, |_, _| count += 1);
        assert_eq!(count, 12, "clipped to the image");
    }
}
