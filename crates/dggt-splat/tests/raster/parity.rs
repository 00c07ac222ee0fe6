//! Parity with gsplat 1.5.3 (`classic`, pinhole, RGB+ED) on the three shared reference cases: images,
//! projection and the gradients of `L = Σ rgb·W1 + Σ alpha·W2 + Σ ED·W3`.
//!
//! The vectors live beside the repository in `shared/parity/raster` (`$DGGT_PARITY_DIR/raster` when set; the
//! variable names the shared `parity` folder). Their README describes how they were computed.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use dggt_geom::ImageSize;
use dggt_splat::{
    CullReason, Gaussians, ImageGrads, Opacities, RasterSettings, ViewBatch, rasterize, rasterize_backward,
};

pub fn parity_dir() -> PathBuf {
    dggt_test_data::parity("raster")
}

pub struct Tensors(HashMap<String, (Vec<usize>, Vec<f32>)>);

impl Tensors {
    pub fn load(path: &Path) -> Self {
        let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let file = safetensors::SafeTensors::deserialize(&bytes)
            .unwrap_or_else(|e| panic!("{} is not a safetensors file: {e}", path.display()));
        let tensors = file
            .tensors()
            .into_iter()
            .map(|(name, view)| {
                assert_eq!(view.dtype(), safetensors::Dtype::F32, "{name} in {}", path.display());
                let values =
                    view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
                (name, (view.shape().to_vec(), values))
            })
            .collect();
        Self(tensors)
    }

    pub fn get(&self, name: &str) -> &[f32] {
        &self.0.get(name).unwrap_or_else(|| panic!("tensor {name} missing")).1
    }

    pub fn shape(&self, name: &str) -> &[usize] {
        &self.0.get(name).unwrap_or_else(|| panic!("tensor {name} missing")).0
    }
}

/// Largest absolute difference and the reference's largest magnitude, over the entries `keep` selects.
pub fn compare(actual: &[f32], expected: &[f32], keep: impl Fn(usize) -> bool) -> (f64, f64) {
    assert_eq!(actual.len(), expected.len(), "compared buffers of one length");
    let mut max_error = 0.0f64;
    let mut max_reference = 0.0f64;
    for (k, (a, e)) in actual.iter().zip(expected).enumerate() {
        if keep(k) {
            assert!(a.is_finite(), "non-finite value at {k}");
            max_error = max_error.max((*a as f64 - *e as f64).abs());
            max_reference = max_reference.max((*e as f64).abs());
        }
    }
    (max_error, max_reference)
}

/// Tolerance of one tensor: `|a - b| <= atol + rtol · max|reference|`.
#[derive(Clone, Copy)]
pub struct Tolerance {
    pub atol: f64,
    pub rtol: f64,
}

/// Colour and alpha: the reference's own f32-vs-f64 spread reaches 1.8e-5 (case b).
pub const IMAGE: Tolerance = Tolerance { atol: 3e-5, rtol: 0.0 };
/// Expected depth divides by alpha.
pub const DEPTH: Tolerance = Tolerance { atol: 1e-4, rtol: 0.0 };
/// Gradients: half the 1e-3 the reference suggests; measured at most 1e-4.
pub const GRADIENT: Tolerance = Tolerance { atol: 1e-5, rtol: 5e-4 };

pub fn check(case: &str, name: &str, (error, reference): (f64, f64), tol: Tolerance) {
    let bound = tol.atol + tol.rtol * reference;
    eprintln!(
        "{case:<28} {name:<20} max abs err {error:.2e}  rel {:.2e}  (bound {bound:.1e})",
        error / reference.max(f64::MIN_POSITIVE)
    );
    assert!(error <= bound, "{case} {name}: max abs error {error:.3e} exceeds {bound:.3e} (max |ref| {reference:.3e})");
}

/// Checks `actual` against the float32 reference `name` and its float64 recomputation `f64_name`.
pub fn check_both(case: &str, name: &str, actual: &[f32], outputs: &Tensors, tol: Tolerance) {
    check(case, name, compare(actual, outputs.get(name), |_| true), tol);
    let f64_name = format!("f64_{name}");
    check(case, &f64_name, compare(actual, outputs.get(&f64_name), |_| true), tol);
}

fn run_case(case: &str) {
    let dir = parity_dir().join(case);
    let inputs = Tensors::load(&dir.join("inputs.safetensors"));
    let outputs = Tensors::load(&dir.join("outputs.safetensors"));
    let shape = inputs.shape("W1");
    let (views_count, height, width) = (shape[0], shape[1], shape[2]);
    let count = inputs.shape("means")[0];
    let size = ImageSize::new(width as u32, height as u32).unwrap();
    let views = ViewBatch::from_matrices(inputs.get("viewmats"), inputs.get("Ks"), size).unwrap();
    let gaussians = Gaussians::new(
        inputs.get("means"),
        inputs.get("quats"),
        inputs.get("scales"),
        Opacities::Shared(inputs.get("opacities")),
        inputs.get("colors"),
        3,
    )
    .unwrap();
    let settings = RasterSettings::default();
    let forward = rasterize(&gaussians, &views, &settings).unwrap();

    check_both(case, "render_rgb", &forward.images.colors, &outputs, IMAGE);
    check_both(case, "render_alpha", &forward.images.alpha, &outputs, IMAGE);
    check_both(case, "render_depth_ed", &forward.images.depth, &outputs, DEPTH);

    // Projection. The reference marks visibility with the 3.33-sigma box (`proj_radii`); this crate uses the
    // kernel's tighter opacity-aware box (`proj_radii_cuda_style`), so it may additionally cull Gaussians whose
    // tighter box misses the image. Those can reach no pixel with alpha >= 1/255.
    let radii = outputs.get("proj_radii");
    let kernel_radii = outputs.get("proj_radii_cuda_style");
    let means2d = outputs.get("proj_means2d");
    let projection = &forward.projection;
    let mut tighter = 0;
    for k in 0..views_count * count {
        let expected_visible = radii[2 * k] > 0.0 || radii[2 * k + 1] > 0.0;
        let visible = projection.culled[k].is_none();
        let what = format!("{case}: view {} Gaussian {} ({:?})", k / count, k % count, projection.culled[k]);
        if visible {
            assert!(expected_visible, "{what} is culled by the reference");
            for axis in 0..2 {
                let (ours, theirs) = (projection.radii[2 * k + axis] as f32, kernel_radii[2 * k + axis]);
                assert!((ours - theirs).abs() <= 1.0, "{what}: radius axis {axis}: {ours} vs {theirs}");
            }
        } else if expected_visible {
            assert_eq!(projection.culled[k], Some(CullReason::OutsideImage), "{what} is visible in the reference");
            let (rx, ry) = (kernel_radii[2 * k], kernel_radii[2 * k + 1]);
            let (mx, my) = (means2d[2 * k], means2d[2 * k + 1]);
            let outside = mx + rx <= 0.0 || mx - rx >= width as f32 || my + ry <= 0.0 || my - ry >= height as f32;
            assert!(outside, "{what}: the kernel box {rx}x{ry} at ({mx}, {my}) overlaps the image");
            tighter += 1;
        }
    }
    eprintln!("{case:<28} visibility           identical except {tighter} culled by the tighter opacity-aware box");
    let kept = |k: usize| projection.culled[k].is_none();
    check(
        case,
        "proj_means2d",
        compare(&projection.means2d, outputs.get("proj_means2d"), |k| kept(k / 2)),
        Tolerance { atol: 1e-5, rtol: 1e-6 },
    );
    check(
        case,
        "proj_depths",
        compare(&projection.depths, outputs.get("proj_depths"), kept),
        Tolerance { atol: 1e-6, rtol: 1e-6 },
    );
    check(
        case,
        "proj_conics",
        compare(&projection.conics, outputs.get("proj_conics"), |k| kept(k / 3)),
        Tolerance { atol: 1e-6, rtol: 2e-4 },
    );
    for (v, stats) in forward.stats.iter().enumerate() {
        let reasons = &projection.culled[v * count..(v + 1) * count];
        assert_eq!(stats.gaussians, count, "{case}: view {v} counts every Gaussian");
        assert_eq!(stats.kept, reasons.iter().filter(|r| r.is_none()).count(), "{case}: view {v} kept");
        assert_eq!(
            stats.near_plane,
            reasons.iter().filter(|r| **r == Some(CullReason::NearPlane)).count(),
            "{case}: view {v} behind the near plane"
        );
        assert_eq!(stats.tile_intersections, forward.bins[v].len(), "{case}: view {v} tile intersections");
        eprintln!("{case:<28} view {v}: {stats}");
    }
    if case.starts_with("case_b") {
        // Groups 0-29 (behind camera 0) and 80-81 (inside its near plane).
        for i in (0..30).chain(80..82) {
            assert_eq!(projection.culled[i], Some(CullReason::NearPlane), "{case}: Gaussian {i}");
        }
    }

    // Gradients.
    let grads =
        ImageGrads { colors: Some(inputs.get("W1")), alpha: Some(inputs.get("W2")), depth: Some(inputs.get("W3")) };
    let loss: f64 = [(&forward.images.colors, "W1"), (&forward.images.alpha, "W2"), (&forward.images.depth, "W3")]
        .iter()
        .map(|(values, weights)| {
            values.iter().zip(inputs.get(weights)).map(|(a, b)| *a as f64 * *b as f64).sum::<f64>()
        })
        .sum();
    let expected_loss = outputs.get("loss")[0] as f64;
    assert!((loss - expected_loss).abs() <= 1e-5 * expected_loss.abs(), "{case}: loss {loss} vs {expected_loss}");
    eprintln!("{case:<28} loss                 {loss:.6} vs {expected_loss:.6}");

    let backward = rasterize_backward(&gaussians, &views, &settings, &forward, &grads).unwrap();
    let Opacities::Shared(grad_opacities) = &backward.opacities else {
        panic!("shared opacities give shared gradients")
    };
    check_both(case, "grad_means", &backward.means, &outputs, GRADIENT);
    check_both(case, "grad_quats", &backward.quats, &outputs, GRADIENT);
    check_both(case, "grad_scales", &backward.scales, &outputs, GRADIENT);
    check_both(case, "grad_opacities", grad_opacities, &outputs, GRADIENT);
    check_both(case, "grad_colors", &backward.colors, &outputs, GRADIENT);
}

#[test]
fn matches_gsplat_on_the_shared_reference_cases() {
    for case in ["case_a_50g_32x24_1cam", "case_b_300g_64x48_2cam", "case_c_80g_40x40_degenerate"] {
        run_case(case);
    }
}
