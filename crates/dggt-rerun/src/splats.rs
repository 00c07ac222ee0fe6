//! Gaussians as rerun's `GaussianSplats3D`: centres, linear scales (standard deviations), rotations and RGBA
//! colours whose alpha is the opacity, all in natural form (the PLY's log scales and logit opacities undone by
//! the reader).

use dggt_formats::ply::GaussianCloud;

/// `cloud` as splats. Quaternions are written `x y z w` (rerun's order) from the cloud's `w x y z`.
pub fn splats(cloud: &GaussianCloud) -> rerun::GaussianSplats3D {
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    let colours = cloud.colors.iter().zip(&cloud.opacities).map(|(rgb, &alpha)| {
        rerun::Color::from_unmultiplied_rgba(byte(rgb[0]), byte(rgb[1]), byte(rgb[2]), byte(alpha))
    });
    let rotations = cloud.quats_wxyz.iter().map(|&[w, x, y, z]| rerun::Quaternion::from_xyzw([x, y, z, w]));
    rerun::GaussianSplats3D::new(cloud.means.iter().copied())
        .with_scales(cloud.scales.iter().copied())
        .with_quaternions(rotations)
        .with_colors(colours)
}
