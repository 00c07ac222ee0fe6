//! The Pareto front of (time, quality) points: the configurations no other configuration beats on both
//! run time (lower is better) and quality (higher is better, e.g. PSNR in dB).

/// `true` for each point that no other point dominates. A point dominates another when it is at least as fast
/// and at least as good, and strictly better in one of the two. Points with a NaN coordinate are never on the
/// front and dominate nothing; an infinite quality (an exact match) is the best possible.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<bool> {
    let valid = |p: &(f64, f64)| !p.0.is_nan() && !p.1.is_nan();
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            valid(p)
                && !points
                    .iter()
                    .enumerate()
                    .any(|(j, q)| j != i && valid(q) && q.0 <= p.0 && q.1 >= p.1 && (q.0 < p.0 || q.1 > p.1))
        })
        .collect()
}
