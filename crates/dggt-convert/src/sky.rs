//! Approximate sky masks from lidar (`sky_masks/{t:03}_{cam}.png`, 255 = sky), for exports whose converter has
//! no image segmentation: per image column, the rows above the highest lidar return projected into that column
//! (less a margin) are marked sky.
//!
//! This is an **approximation**, not drivestudio's SegFormer masks: a column whose returns all lie on the road
//! marks the distant buildings above them as sky too, and a column without any return (within a few columns
//! either side) is marked nowhere. The export says so in `sky_masks/SOURCE.txt`. Points are given in the camera's
//! ego frame and projected with the camera's lens model ([`EgoCamera::project_inside`]).

use dggt_data::{ExportLayout, images, io};
use dggt_geom::glam::DVec3;
use image::{GrayImage, Luma};

use crate::camera::EgoCamera;
use crate::error::Result;

/// Whether and how a converter writes sky masks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SkyMasks {
    /// No `sky_masks/` (the trainer then skips its sky-opacity term for the scene).
    #[default]
    None,
    /// Approximate masks from the projected lidar returns.
    Lidar,
}

impl SkyMasks {
    /// The name a done marker records.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Lidar => "lidar",
        }
    }
}

/// Rows left unmarked above the highest return of a column, as a fraction of the image height.
pub const MARGIN_OF_HEIGHT: f64 = 0.02;
/// Columns either side whose returns also bound a column (lidar columns are sparser than pixels), as a fraction
/// of the image width.
pub const NEIGHBOURHOOD_OF_WIDTH: f64 = 0.01;

/// What `sky_masks/SOURCE.txt` says about masks made here.
pub const SOURCE_NOTE: &str = "Approximate sky masks from lidar (dggt convert --sky-masks lidar): in each image \
column, the rows above the highest projected lidar return less a 2% margin are sky; columns without returns \
have no sky. Not a semantic segmentation.\n";

/// The sky mask of one view: `points_in_ego` are the lidar returns in the camera's ego frame.
pub fn lidar_sky_mask(camera: &EgoCamera, points_in_ego: impl IntoIterator<Item = DVec3>) -> GrayImage {
    let (width, height) = (camera.size.width as usize, camera.size.height as usize);
    let mut highest = vec![usize::MAX; width];
    for point in points_in_ego {
        if let Some(pixel) = camera.project_inside(point) {
            let (col, row) = (pixel.x as usize, pixel.y as usize);
            highest[col] = highest[col].min(row);
        }
    }
    let reach = (width as f64 * NEIGHBOURHOOD_OF_WIDTH).round() as usize;
    let margin = (height as f64 * MARGIN_OF_HEIGHT).ceil() as usize;
    let mut mask = GrayImage::new(camera.size.width, camera.size.height);
    for col in 0..width {
        let window = col.saturating_sub(reach)..(col + reach + 1).min(width);
        let top = highest[window].iter().copied().min().unwrap_or(usize::MAX);
        if top == usize::MAX {
            continue;
        }
        for row in 0..top.saturating_sub(margin) {
            mask.put_pixel(col as u32, row as u32, Luma([255]));
        }
    }
    mask
}

/// Writes view (`frame`, `camera`)'s mask, and the note that the masks are approximate.
pub fn write_lidar_sky_mask(layout: &ExportLayout, frame: usize, camera: usize, mask: &GrayImage) -> Result<()> {
    let note = layout.root().join("sky_masks/SOURCE.txt");
    if !note.is_file() {
        io::write_atomically(&note, SOURCE_NOTE.as_bytes())?;
    }
    Ok(images::write_png_gray(&layout.sky_mask(frame, camera), mask)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Distortion;
    use dggt_geom::{ImageSize, PinholeIntrinsics, Rigid};

    fn forward_camera() -> EgoCamera {
        EgoCamera {
            intrinsics: PinholeIntrinsics::new(100.0, 100.0, 100.0, 50.0).unwrap(),
            distortion: Distortion::default(),
            camera_from_ego: dggt_geom::axes::ego_from_opencv_camera(&Rigid::IDENTITY).inverse(),
            size: ImageSize::new(200, 100).unwrap(),
        }
    }

    #[test]
    fn columns_above_the_highest_return_are_sky_and_columns_without_returns_are_not() {
        // A wall 10 m ahead, 2.05 m up, spanning ego y in [-0.95, 0.95]: pixels u = 100 - 10 y in [90.5, 109.5],
        // top row v = 50 - 20.5 = 29.5.
        let wall = (0..=38).map(|i| DVec3::new(10.0, -0.95 + i as f64 * 0.05, 2.05));
        let mask = lidar_sky_mask(&forward_camera(), wall);
        let sky = |col: u32, row: u32| mask.get_pixel(col, row).0[0] == 255;
        // Margin 2 rows (2% of 100) above row 29: rows 0..27 are sky.
        assert!(sky(100, 0) && sky(100, 26), "above the wall");
        assert!(!sky(100, 27) && !sky(100, 29) && !sky(100, 60), "at and below the top return");
        // The wall covers columns 90..=109; the neighbourhood reaches 2 columns further.
        assert!(sky(88, 5) && !sky(87, 5) && !sky(20, 5), "no returns, no sky");
    }
}
