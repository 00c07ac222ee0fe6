//! Coarse dynamic masks: each annotated box projected into a camera and filled as its axis-aligned bounding
//! rectangle, per class (`dynamic_masks/{all,human,vehicle}/`), the way drivestudio's converters draw them.
//!
//! A box is drawn only when all 8 corners project inside the image in front of the camera. Its rectangle covers
//! rows `floor(v_min) .. floor(v_min) + floor(v_max - v_min)` (end exclusive) and the same for columns. Which boxes
//! are drawn is the dataset's [`MaskRule`]. `all` is `human` ∪ `vehicle`.

use dggt_data::{DynamicMaskKind, ExportLayout, images};
use dggt_geom::glam::DVec2;
use image::{GrayImage, Luma};

use crate::boxes::{AnnotatedBox, ObjectClass};
use crate::camera::EgoCamera;
use crate::error::Result;

/// Which boxes a dataset's masks show.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MaskRule {
    /// Waymo: boxes the lidar saw, moving faster than this horizontal speed (m/s).
    SeenAndFasterThan(f64),
    /// nuScenes, Argoverse 2: every box of a masked class.
    EveryBox,
}

impl MaskRule {
    fn draws(self, object: &AnnotatedBox) -> bool {
        match self {
            Self::SeenAndFasterThan(speed) => object.has_points && object.speed > speed,
            Self::EveryBox => true,
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
    /// Draws the boxes that `rule` keeps into `camera`.
    pub fn draw(camera: &EgoCamera, boxes: &[AnnotatedBox], rule: MaskRule) -> Self {
        let (width, height) = (camera.size.width, camera.size.height);
        let mut masks = Self {
            all: GrayImage::new(width, height),
            human: GrayImage::new(width, height),
            vehicle: GrayImage::new(width, height),
        };
        for object in boxes.iter().filter(|object| rule.draws(object)) {
            let Some((min, max)) = projected_bounds(camera, object) else { continue };
            let class_mask = match object.class {
                ObjectClass::Vehicle => &mut masks.vehicle,
                ObjectClass::Human => &mut masks.human,
            };
            fill_rectangle(class_mask, min, max);
            fill_rectangle(&mut masks.all, min, max);
        }
        masks
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
        let masks = DynamicMasks::draw(&camera(), &[walker], MaskRule::SeenAndFasterThan(1.0));
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
        let masks = DynamicMasks::draw(&camera(), &boxes, MaskRule::SeenAndFasterThan(1.0));
        assert!(masks.all.pixels().all(|p| p.0[0] == 0));
        let every = DynamicMasks::draw(&camera(), &boxes, MaskRule::EveryBox);
        assert!(every.vehicle.pixels().any(|p| p.0[0] == 255), "without the speed rule the centred boxes are drawn");
    }
}
