//! Scoring renders: resizing them to the reference size, their mean PSNR, SSIM and LPIPS against the exact
//! render or the ground truth, and the Pareto fronts of total time against that error.

use burn::tensor::{Device, Tensor, TensorData};
use dggt_geom::ImageSize;
use dggt_losses::Lpips;
use dggt_metrics::ImageShape;
use dggt_model::host::host_f32;

use super::outcome::{ErrorMetrics, MeasuredRow, RowOutcome};
use crate::error::BenchError;
use crate::pareto::pareto_front;

/// `[H, W, 3]` `from` resized to `to` (full frame to full frame, triangle filter); a copy when equal.
pub fn resize_rgb(image: &[f32], from: ImageSize, to: ImageSize) -> Vec<f32> {
    if from == to {
        return image.to_vec();
    }
    let buffer = image::Rgb32FImage::from_raw(from.width, from.height, image.to_vec())
        .expect("a render holds width x height x 3 values");
    let resized = image::imageops::resize(&buffer, to.width, to.height, image::imageops::FilterType::Triangle);
    resized.into_raw().into_iter().map(|v| v.clamp(0.0, 1.0)).collect()
}

/// Mean PSNR, SSIM (and LPIPS) of `images` against `references`, all `[H, W, 3]` at `size`.
pub(super) fn compare(
    images: &[Vec<f32>],
    references: &[Vec<f32>],
    size: ImageSize,
    lpips: Option<&Lpips>,
    device: &Device,
) -> Result<ErrorMetrics, BenchError> {
    let shape = ImageShape::new(size.height as usize, size.width as usize, 3);
    let (mut psnr, mut ssim) = (0.0, 0.0);
    for (image, reference) in images.iter().zip(references) {
        psnr += dggt_metrics::psnr(image, reference)?;
        ssim += dggt_metrics::ssim(image, reference, shape)?.value;
    }
    let n = images.len().max(1) as f64;
    let lpips = match lpips {
        Some(net) => {
            let batch = |list: &[Vec<f32>]| {
                let data: Vec<f32> = list.iter().flatten().copied().collect();
                Tensor::<4>::from_data(TensorData::new(data, [list.len(), shape.height, shape.width, 3]), device)
            };
            let values = net.eval(batch(images), batch(references))?;
            let values = host_f32(values, "LPIPS values")?;
            Some(values.iter().map(|&v| v as f64).sum::<f64>() / values.len().max(1) as f64)
        }
        None => None,
    };
    Ok(ErrorMetrics { psnr_db: psnr / n, ssim: ssim / n, lpips })
}

/// Marks the Pareto fronts of total time against PSNR vs exact and vs truth.
pub(super) fn mark_pareto(rows: &mut [RowOutcome]) {
    let measured: Vec<usize> = (0..rows.len()).filter(|&i| rows[i].measured().is_some()).collect();
    let points = |quality: fn(&MeasuredRow) -> f64, rows: &[RowOutcome]| -> Vec<(f64, f64)> {
        measured.iter().filter_map(|&i| rows[i].measured().map(|r| (r.times.total_ms, quality(r)))).collect()
    };
    let exact = pareto_front(&points(|r| r.vs_exact.psnr_db, rows));
    let truth = pareto_front(&points(|r| r.vs_truth.psnr_db, rows));
    for (k, &i) in measured.iter().enumerate() {
        if let RowOutcome::Measured(row) = &mut rows[i] {
            row.pareto_vs_exact = exact[k];
            row.pareto_vs_truth = truth[k];
        }
    }
}
