//! The project's values as rerun components, shared by every recording: camera poses and pinholes (OpenCV axes),
//! 8-bit images and depth images in metres; and the layouts' tabs of one view's images.

use dggt_geom::{ImageSize, PinholeIntrinsics, WorldFromCamera};

/// A world-from-camera pose as rerun's transform of the camera's entity (quaternion written `x y z w`).
pub fn camera_transform(world_from_camera: &WorldFromCamera) -> rerun::Transform3D {
    let [x, y, z, w] = world_from_camera.rotation().to_array().map(|v| v as f32);
    let translation = world_from_camera.translation().to_array().map(|v| v as f32);
    rerun::Transform3D::from_translation_rotation(translation, rerun::Quaternion::from_xyzw([x, y, z, w]))
}

/// A pinhole in pixels of an image of `size`, with OpenCV camera axes (x right, y down, z forward).
pub fn pinhole(k: &PinholeIntrinsics, size: ImageSize) -> rerun::Pinhole {
    rerun::Pinhole::from_focal_length_and_resolution(
        [k.fx as f32, k.fy as f32],
        [size.width as f32, size.height as f32],
    )
    .with_principal_point([k.cx as f32, k.cy as f32])
    .with_camera_xyz(rerun::components::ViewCoordinates::RDF)
}

/// Row-major `[H, W, 3]` values in `[0, 1]` (clamped) as an 8-bit RGB image.
pub fn rgb_image(size: ImageSize, rgb: &[f32]) -> rerun::Image {
    rerun::Image::from_rgb24(rgb.iter().map(|&v| byte(v)).collect::<Vec<u8>>(), [size.width, size.height])
}

/// Row-major values in `[0, 1]` (clamped) as an 8-bit grey image.
pub fn grey_image(size: ImageSize, values: &[f32]) -> rerun::Image {
    rerun::Image::from_l8(values.iter().map(|&v| byte(v)).collect::<Vec<u8>>(), [size.width, size.height])
}

/// Row-major depths in world units (metres) as a depth image.
pub fn depth_image(size: ImageSize, depths: &[f32]) -> rerun::DepthImage {
    let bytes: Vec<u8> = depths.iter().flat_map(|d| d.to_le_bytes()).collect();
    rerun::DepthImage::from_data_type_and_bytes(bytes, [size.width, size.height], rerun::ChannelDatatype::F32)
        .with_meter(1.0)
}

/// An 8-bit RGB image as it is.
pub fn rgb8_image(image: &image::RgbImage) -> rerun::Image {
    rerun::Image::from_rgb24(image.as_raw().clone(), [image.width(), image.height()])
}

/// An 8-bit grey image as it is.
pub fn grey8_image(image: &image::GrayImage) -> rerun::Image {
    rerun::Image::from_l8(image.as_raw().clone(), [image.width(), image.height()])
}

/// Tabs of 2D views titled `TITLE: PART`, each showing the entity `ORIGIN/PART`.
pub fn part_tabs(title: &str, origin: &str, parts: &[&str]) -> rerun::blueprint::ContainerLike {
    use rerun::blueprint::{Spatial2DView, Tabs};
    let tab = |part: &&str| {
        Spatial2DView::new(format!("{title}: {part}"))
            .with_origin(origin)
            .with_contents([format!("$origin/{part}")])
            .into()
    };
    Tabs::new(parts.iter().map(tab)).into()
}

fn byte(value: f32) -> u8 {
    (value.clamp(0.0, 1.0) * 255.0).round() as u8
}
