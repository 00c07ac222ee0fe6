//! Decoding one view of a scene into what a training or inference step consumes: the preprocessed image,
//! masks, intrinsics adjusted to the preprocessing, and the ground-truth pose.

use dggt_geom::{PinholeIntrinsics, WorldFromCamera};

use crate::decoded::DecodedViews;
use crate::error::Result;
use crate::images;
use crate::preprocess::{BinaryMask, PlanarImage, Preprocess};
use crate::scene::Scene;

/// One view ready for the network.
#[derive(Debug, Clone)]
pub struct PreparedView {
    /// Position in [`Scene::frames`].
    pub frame: usize,
    /// Position in [`Scene::cameras`].
    pub camera: usize,
    /// Seconds since the first frame of the scene.
    pub timestamp: f64,
    pub image: PlanarImage,
    pub sky_mask: Option<BinaryMask>,
    /// The refined dynamic mask when the export has one, else the box-based one.
    pub dynamic_mask: Option<BinaryMask>,
    /// Intrinsics of the preprocessed image.
    pub intrinsics: PinholeIntrinsics,
    /// Ground-truth pose.
    pub world_from_camera: WorldFromCamera,
}

/// Decodes and preprocesses view `(frame, camera)` (positions in the scene).
pub fn prepare_view(scene: &Scene, frame: usize, camera: usize, preprocess: &Preprocess) -> Result<PreparedView> {
    prepare_view_cached(scene, frame, camera, preprocess, &DecodedViews::none())
}

/// [`prepare_view`], taking the image and masks from `cache` where it keeps them (and keeping them there when it
/// has room). `cache` must belong to `preprocess`.
pub fn prepare_view_cached(
    scene: &Scene,
    frame: usize,
    camera: usize,
    preprocess: &Preprocess,
    cache: &DecodedViews,
) -> Result<PreparedView> {
    let view = scene.view(frame, camera);
    let scene_camera = &scene.cameras[camera];
    let plan = preprocess.plan(scene_camera.size)?;
    let image = cache.image(&view.files.image, || {
        let rgb = images::read_rgb(&view.files.image)?;
        images::expect_size(
            &view.files.image,
            dggt_geom::ImageSize { width: rgb.width(), height: rgb.height() },
            scene_camera.size,
        )?;
        plan.image(&rgb)
    })?;
    let mask = |path: &Option<std::path::PathBuf>| -> Result<Option<BinaryMask>> {
        let Some(path) = path else { return Ok(None) };
        let mask = cache.mask(path, || {
            let gray = images::read_gray(path)?;
            images::expect_size(
                path,
                dggt_geom::ImageSize { width: gray.width(), height: gray.height() },
                scene_camera.size,
            )?;
            plan.mask(&gray)
        })?;
        Ok(Some(mask))
    };
    let dynamic_source = view.files.fine_dynamic_mask.as_ref().or(view.files.dynamic_mask.as_ref()).cloned();
    Ok(PreparedView {
        frame,
        camera,
        timestamp: scene.frames[frame].timestamp,
        image,
        sky_mask: mask(&view.files.sky_mask)?,
        dynamic_mask: mask(&dynamic_source)?,
        intrinsics: plan.intrinsics(&scene_camera.intrinsics),
        world_from_camera: view.world_from_camera,
    })
}
