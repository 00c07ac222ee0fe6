//! What a reconstruction writes is finite: every value of a file (a camera, a depth or probability map, a
//! Gaussian, a render) is checked before the file is written, and a value that is not a number or infinite fails
//! the reconstruction naming the file, the quantity and its element, rather than reaching disk (where NaN reads
//! back as whatever each format makes of it: a black pixel, a zero depth, a default rotation).

use std::path::Path;

use dggt_formats::ply::GaussianCloud;
use dggt_geom::PosedCamera;

use crate::error::ReconstructError;

/// Checks that every one of `values`, the `what` of the file `path`, is finite.
pub fn check(path: &Path, what: &str, values: impl IntoIterator<Item = f64>) -> Result<(), ReconstructError> {
    match values.into_iter().enumerate().find(|(_, value)| !value.is_finite()) {
        Some((element, value)) => {
            Err(ReconstructError::NonFinite { path: path.to_path_buf(), what: what.to_string(), element, value })
        }
        None => Ok(()),
    }
}

/// [`check`] of `f32` values.
pub fn check_f32(path: &Path, what: &str, values: &[f32]) -> Result<(), ReconstructError> {
    check(path, what, values.iter().map(|&value| f64::from(value)))
}

/// Checks every field of every Gaussian of `cloud`, to be written to `path`.
pub fn check_cloud(path: &Path, cloud: &GaussianCloud) -> Result<(), ReconstructError> {
    check_f32(path, "Gaussian means", cloud.means.as_flattened())?;
    check_f32(path, "Gaussian rotations", cloud.quats_wxyz.as_flattened())?;
    check_f32(path, "Gaussian scales", cloud.scales.as_flattened())?;
    check_f32(path, "Gaussian opacities", &cloud.opacities)?;
    check_f32(path, "Gaussian colours", cloud.colors.as_flattened())
}

/// Checks the intrinsics and pose of each of `cameras`, to be written to `path`.
pub fn check_cameras(path: &Path, cameras: &[PosedCamera]) -> Result<(), ReconstructError> {
    for camera in cameras {
        let k = camera.intrinsics;
        check(path, "camera intrinsics", [k.fx, k.fy, k.cx, k.cy])?;
        let pose = &camera.world_from_camera;
        check(path, "camera rotations", pose.rotation().to_array())?;
        check(path, "camera positions", pose.translation().to_array())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_finite_value_is_named_with_its_file_quantity_and_element() {
        let path = Path::new("out/depth/v0.npy");
        check_f32(path, "depth", &[1.0, 2.0, f32::MAX]).unwrap();
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let error = check_f32(path, "depth", &[1.0, 2.0, bad, 3.0]).unwrap_err();
            assert!(matches!(&error, ReconstructError::NonFinite { element: 2, .. }), "{error:?}");
            let text = error.to_string();
            assert!(
                text.contains("out/depth/v0.npy") && text.contains("depth") && text.contains("element 2"),
                "{text}"
            );
        }
    }

    /// Puts a non-finite value into one field of a cloud.
    type Spoil = fn(&mut GaussianCloud);

    #[test]
    fn every_field_of_a_cloud_is_checked() {
        let path = Path::new("static.ply");
        let cloud = GaussianCloud {
            means: vec![[0.0, 1.0, 2.0]; 2],
            quats_wxyz: vec![[1.0, 0.0, 0.0, 0.0]; 2],
            scales: vec![[0.1; 3]; 2],
            opacities: vec![0.5; 2],
            colors: vec![[0.2; 3]; 2],
        };
        check_cloud(path, &cloud).unwrap();
        let spoilt: [(&str, Spoil); 5] = [
            ("means", |c| c.means[1][2] = f32::NAN),
            ("rotations", |c| c.quats_wxyz[0][3] = f32::INFINITY),
            ("scales", |c| c.scales[1][0] = f32::NAN),
            ("opacities", |c| c.opacities[1] = f32::NAN),
            ("colours", |c| c.colors[0][1] = f32::NEG_INFINITY),
        ];
        for (field, spoil) in spoilt {
            let mut bad = cloud.clone();
            spoil(&mut bad);
            let error = check_cloud(path, &bad).unwrap_err().to_string();
            assert!(error.contains(&format!("Gaussian {field}")), "{field}: {error}");
        }
    }
}
