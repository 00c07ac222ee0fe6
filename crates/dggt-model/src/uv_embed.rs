//! The DPT heads' positional embedding: sin/cos features of a normalised UV grid, added (scaled by 0.1) to
//! feature maps before resizing and before the output convolutions.
//!
//! The grid spans `[-a, a] x [-b, b]` with `a = r / sqrt(r^2 + 1)`, `b = 1 / sqrt(r^2 + 1)`, `r` the image
//! aspect ratio (W / H), shrunk by `(n - 1) / n` per axis so samples sit at cell centres; it is sampled with
//! `linspace` in `f32`. Channels: `[sin(u w_k), cos(u w_k), sin(v w_k), cos(v w_k)]` for
//! `w_k = omega0^(-k / (C / 4))`, `k < C / 4`, evaluated in `f64` and rounded to `f32`.

/// `torch.linspace(start, end, steps)` in `f32`: the first half counts up from `start`, the second half down
/// from `end`.
fn linspace_f32(start: f64, end: f64, steps: usize) -> Vec<f32> {
    if steps == 1 {
        return vec![start as f32];
    }
    let (start, end) = (start as f32, end as f32);
    let step = (end - start) / (steps - 1) as f32;
    let half = steps / 2;
    (0..steps).map(|i| if i < half { start + step * i as f32 } else { end - step * (steps - i - 1) as f32 }).collect()
}

/// Row-major `[channels, height, width]` embedding of a `height x width` feature map of an image with the
/// given aspect ratio (width / height), multiplied by `ratio`.
pub fn uv_sincos_embedding(
    channels: usize,
    [height, width]: [usize; 2],
    aspect_ratio: f64,
    omega_0: f64,
    ratio: f32,
) -> Vec<f32> {
    assert!(channels.is_multiple_of(4), "UV embedding needs channels divisible by 4, got {channels}");
    let diagonal = (aspect_ratio * aspect_ratio + 1.0).sqrt();
    let (span_x, span_y) = (aspect_ratio / diagonal, 1.0 / diagonal);
    let extent = |span: f64, n: usize| span * (n as f64 - 1.0) / n as f64;
    let u = linspace_f32(-extent(span_x, width), extent(span_x, width), width);
    let v = linspace_f32(-extent(span_y, height), extent(span_y, height), height);
    let quarter = channels / 4;
    let omega: Vec<f64> = (0..quarter).map(|k| 1.0 / omega_0.powf(k as f64 / quarter as f64)).collect();
    let plane = height * width;
    let mut out = vec![0.0f32; channels * plane];
    for (y, &v_y) in v.iter().enumerate() {
        for (x, &u_x) in u.iter().enumerate() {
            let cell = y * width + x;
            for (axis, coordinate) in [u_x, v_y].into_iter().enumerate() {
                for (k, w) in omega.iter().enumerate() {
                    let angle = coordinate as f64 * w;
                    let base = axis * 2 * quarter;
                    out[(base + k) * plane + cell] = angle.sin() as f32 * ratio;
                    out[(base + quarter + k) * plane + cell] = angle.cos() as f32 * ratio;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linspace_is_symmetric_and_hits_ends() {
        let l = linspace_f32(-0.75, 0.75, 4);
        assert_eq!(l, vec![-0.75, -0.25, 0.25, 0.75]);
        assert_eq!(linspace_f32(0.0, 0.0, 1), vec![0.0]);
    }

    #[test]
    fn square_grid_centre_channels() {
        // 1x1 map: u = v = 0, so sin channels vanish and cos channels equal the ratio.
        let e = uv_sincos_embedding(8, [1, 1], 1.0, 100.0, 0.1);
        assert_eq!(e, vec![0.0, 0.0, 0.1, 0.1, 0.0, 0.0, 0.1, 0.1]);
    }
}
