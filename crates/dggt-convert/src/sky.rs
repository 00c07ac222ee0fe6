//! Approximate sky masks from lidar (`sky_masks/{t:03}_{cam}.png`, 255 = sky), for exports whose converter has
//! no image segmentation: per image column, the rows above the highest lidar return projected into that column
//! (less a margin) are marked sky.
//!
//! This is an **approximation**, not drivestudio's SegFormer masks: a column whose returns all lie on the road
//! marks the distant buildings above them as sky too, and a column without any return (within a few columns
//! either side) is marked nowhere. The export says so in `sky_masks/SOURCE.txt`. Points are given in the camera's
//! ego frame and projected with the camera's lens model ([`EgoCamera::project_inside`]).
//!
//! With the lidar's pose ([`TopBeam::Known`]) a column is marked only where the lidar's highest beam passed
//! over what the column shows: when the column's highest return came from the sweep's highest beam (within
//! [`TOP_BEAM_TOLERANCE_DEG`] of the highest elevation any return of the sweep has, in the lidar's own frame),
//! a building taller than the lidar's field of view stands there and what lies above it is unknown, so the
//! column gets no sky. Without it, upper floors above the lidar's reach are painted as sky.

use dggt_data::{ExportLayout, images, io};
use dggt_geom::glam::DVec3;
use dggt_geom::{Ego, Rigid, Sweep};
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

/// How far below the sweep's highest elevation a column's highest return must lie for the beams above it to
/// have passed into the sky (degrees): the spacing of a mechanical lidar's top beams is 1-4 degrees.
pub const TOP_BEAM_TOLERANCE_DEG: f64 = 1.0;

/// Whether the sky mask knows the lidar's beams.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TopBeam {
    /// The lidar's frame (x, y horizontal, z along its spin axis) seen from the camera's ego frame: columns
    /// whose highest return came from the top beam get no sky.
    Known(Rigid<Sweep, Ego>),
    /// Not known: every column with returns gets the rows above its highest one.
    Unknown,
}

/// What `sky_masks/SOURCE.txt` says about masks made here.
pub const SOURCE_NOTE: &str = "Approximate sky masks from lidar (dggt convert --sky-masks lidar): in each image \
column, the rows above the highest projected lidar return less a 2% margin are sky; columns without returns \
have no sky; where the converter knows the lidar's pose (nuScenes layouts), neither have columns whose highest \
return came from the lidar's highest beam (a building taller than its field of view). Not a semantic \
segmentation.\n";

/// The sky mask of one view: `points_in_ego` are the lidar returns in the camera's ego frame.
pub fn lidar_sky_mask(
    camera: &EgoCamera,
    points_in_ego: impl IntoIterator<Item = DVec3>,
    top_beam: TopBeam,
) -> GrayImage {
    let (width, height) = (camera.size.width as usize, camera.size.height as usize);
    let elevation = |point: DVec3| match top_beam {
        TopBeam::Known(lidar_from_ego) => {
            let p = lidar_from_ego.transform_point(point);
            p.z.atan2(p.x.hypot(p.y)).to_degrees()
        }
        TopBeam::Unknown => f64::NEG_INFINITY,
    };
    // Per column: the highest return's row and its elevation.
    let mut highest = vec![(usize::MAX, f64::NEG_INFINITY); width];
    let mut top_elevation = f64::NEG_INFINITY;
    for point in points_in_ego {
        let degrees = elevation(point);
        top_elevation = top_elevation.max(degrees);
        if let Some(pixel) = camera.project_inside(point) {
            let (col, row) = (pixel.x as usize, pixel.y as usize);
            if row < highest[col].0 {
                highest[col] = (row, degrees);
            }
        }
    }
    let reach = (width as f64 * NEIGHBOURHOOD_OF_WIDTH).round() as usize;
    let margin = (height as f64 * MARGIN_OF_HEIGHT).ceil() as usize;
    let mut mask = GrayImage::new(camera.size.width, camera.size.height);
    for col in 0..width {
        let window = col.saturating_sub(reach)..(col + reach + 1).min(width);
        let (top, degrees) = highest[window].iter().copied().min_by_key(|(row, _)| *row).unwrap_or((usize::MAX, 0.0));
        let top_beam_hit = degrees > top_elevation - TOP_BEAM_TOLERANCE_DEG;
        if top == usize::MAX || top_beam_hit {
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
        let mask = lidar_sky_mask(&forward_camera(), wall, TopBeam::Unknown);
        let sky = |col: u32, row: u32| mask.get_pixel(col, row).0[0] == 255;
        // Margin 2 rows (2% of 100) above row 29: rows 0..27 are sky.
        assert!(sky(100, 0) && sky(100, 26), "above the wall");
        assert!(!sky(100, 27) && !sky(100, 29) && !sky(100, 60), "at and below the top return");
        // The wall covers columns 90..=109; the neighbourhood reaches 2 columns further.
        assert!(sky(88, 5) && !sky(87, 5) && !sky(20, 5), "no returns, no sky");
    }

    #[test]
    fn a_column_whose_highest_return_came_from_the_top_beam_gets_no_sky() {
        // The lidar at the ego origin, level. A wall 10 m ahead up to 2.05 m (elevation 11.6 degrees), and
        // elsewhere (behind the camera) a return at 20 degrees: the top beam passed over the wall, so the sky above
        // it is known.
        let lidar_from_ego = Rigid::IDENTITY;
        let wall = || (0..=38).map(|i| DVec3::new(10.0, -0.95 + i as f64 * 0.05, 2.05));
        let behind = DVec3::new(-10.0, 0.0, 10.0 * 20f64.to_radians().tan());
        let open = lidar_sky_mask(&forward_camera(), wall().chain([behind]), TopBeam::Known(lidar_from_ego));
        assert_eq!(open.get_pixel(100, 0).0[0], 255, "beams above the wall went to the sky");
        // The same wall when it is what the top beam hit: a building taller than the lidar sees.
        let tall = lidar_sky_mask(&forward_camera(), wall(), TopBeam::Known(lidar_from_ego));
        assert!(tall.pixels().all(|p| p.0[0] == 0), "nothing above the top beam's return is known to be sky");
        let unknown = lidar_sky_mask(&forward_camera(), wall(), TopBeam::Unknown);
        assert_eq!(unknown.get_pixel(100, 0).0[0], 255, "without the lidar's pose, as before");
    }
}
