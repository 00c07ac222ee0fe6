//! Instance masks (`instances/masks/{t:03}_{cam}.png`, 16-bit): which annotated object each pixel shows, as the
//! key + 1 of `instances/instances_info.json` (0 = none), moving and parked objects alike.
//!
//! Each box is drawn as its projected outline ([`projected_outline`]: the convex hull of its edges cut in front
//! of the camera, clipped to the image), the farthest first, so a nearer object's outline covers what it hides.
//! The same approximation as the outline dynamic masks: an outline covers what its box covers, including what a
//! nearer surface that is not an annotated object (a pole, a wall) hides.

use dggt_data::images::{self, Gray16Image};
use dggt_data::{DataError, ExportLayout};
use image::Luma;

use crate::boxes::AnnotatedBox;
use crate::camera::EgoCamera;
use crate::error::Result;
use crate::instances::InstanceLog;
use crate::masks::{DynamicMaskStyle, farthest_first, for_each_pixel_inside, projected_outline};

/// What `instances/masks/SOURCE.txt` says.
pub const NOTE: &str = "Instance masks: 16-bit PNGs, each pixel the key + 1 of the object of instances_info.json \
    whose box covers it nearest the camera (0: no annotated object), every object of the masked classes, moving or \
    parked, drawn as the projected outline of its 3D box at the camera's own time. Approximate: an outline covers \
    what its box covers, including what a nearer unannotated surface hides.\n";

/// One view's instance mask: `boxes` (already registered in `instances`) as their keys + 1; `None` when a key
/// does not fit 16 bits.
pub fn draw(camera: &EgoCamera, boxes: &[AnnotatedBox], instances: &InstanceLog) -> Option<Gray16Image> {
    let mut mask = Gray16Image::new(camera.size.width, camera.size.height);
    for object in farthest_first(camera, boxes) {
        let Some(key) = instances.key(&object.id) else { continue };
        let value = Luma([u16::try_from(key + 1).ok()?]);
        let outline = projected_outline(camera, object);
        for_each_pixel_inside(&outline, mask.width(), mask.height(), |col, row| mask.put_pixel(col, row, value));
    }
    Some(mask)
}

/// Draws and writes view (`frame`, `camera_id`)'s instance mask.
pub fn write(
    layout: &ExportLayout,
    (frame, camera_id): (usize, usize),
    camera: &EgoCamera,
    boxes: &[AnnotatedBox],
    instances: &InstanceLog,
) -> Result<()> {
    let path = layout.instance_mask(frame, camera_id);
    let mask = draw(camera, boxes, instances).ok_or_else(|| {
        DataError::malformed(&path, "at most 65535 instances (16-bit keys)", format!("{} instances", instances.len()))
    })?;
    images::write_png_gray16(&path, &mask)?;
    Ok(())
}

/// What every converter writes once a scene's frames are done: `instances/` with [`NOTE`] beside the instance
/// masks, and the dynamic masks' note.
pub fn write_instances_and_notes(
    layout: &ExportLayout,
    instances: &InstanceLog,
    dynamic_masks: DynamicMaskStyle,
) -> Result<()> {
    instances.write(layout)?;
    dggt_data::io::write_atomically(&layout.root().join("instances/masks/SOURCE.txt"), NOTE.as_bytes())?;
    dynamic_masks.write_note(layout)
}
