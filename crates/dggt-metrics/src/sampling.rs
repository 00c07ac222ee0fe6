//! Reading the values a metric scores: a map at continuous image coordinates (the pixel there, or bilinear
//! between pixel centres), and the mean of the values that are present.

/// The value of the pixel of a row-major `width x height` map that holds continuous image coordinates `(x, y)`
/// (pixel `(c, r)` covers `[c, c + 1) x [r, r + 1)`; a point on the far border belongs to the last pixel).
/// `None` outside `[0, width] x [0, height]` (the same points [`sample_bilinear`] accepts) or for a map of the
/// wrong length.
pub fn sample_pixel(map: &[f32], width: usize, height: usize, x: f64, y: f64) -> Option<f32> {
    if width == 0 || height == 0 || map.len() != width * height {
        return None;
    }
    if !(0.0..=width as f64).contains(&x) || !(0.0..=height as f64).contains(&y) {
        return None;
    }
    let col = (x.floor() as usize).min(width - 1);
    let row = (y.floor() as usize).min(height - 1);
    Some(map[row * width + col])
}

/// The value of a row-major `width x height` map at continuous image coordinates `(x, y)` (pixel `(c, r)`
/// has its centre at `(c + 0.5, r + 0.5)`), bilinear between the four nearest pixel centres, with the edge
/// pixels extended to the image border. `None` outside `[0, width] x [0, height]` or for a map of the wrong
/// length.
pub fn sample_bilinear(map: &[f32], width: usize, height: usize, x: f64, y: f64) -> Option<f32> {
    if width == 0 || height == 0 || map.len() != width * height {
        return None;
    }
    if !(0.0..=width as f64).contains(&x) || !(0.0..=height as f64).contains(&y) {
        return None;
    }
    let (u, v) = (x - 0.5, y - 0.5);
    let (c0, r0) = (u.floor(), v.floor());
    let (fu, fv) = (u - c0, v - r0);
    let clamp_col = |c: f64| c.clamp(0.0, (width - 1) as f64) as usize;
    let clamp_row = |r: f64| r.clamp(0.0, (height - 1) as f64) as usize;
    let (ca, cb, ra, rb) = (clamp_col(c0), clamp_col(c0 + 1.0), clamp_row(r0), clamp_row(r0 + 1.0));
    let at = |r: usize, c: usize| f64::from(map[r * width + c]);
    let top = at(ra, ca) * (1.0 - fu) + at(ra, cb) * fu;
    let bottom = at(rb, ca) * (1.0 - fu) + at(rb, cb) * fu;
    Some((top * (1.0 - fv) + bottom * fv) as f32)
}

/// Mean of the values present, and how many there were; `None` when there are none.
pub fn mean_present(values: impl IntoIterator<Item = Option<f64>>) -> (Option<f64>, usize) {
    let (sum, count) = values.into_iter().flatten().fold((0.0, 0usize), |(sum, count), value| (sum + value, count + 1));
    ((count > 0).then(|| sum / count as f64), count)
}
