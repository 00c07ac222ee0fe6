//! The learning-rate schedule: linear warm-up from zero, then cosine decay to a floor. A pure function of the
//! step, so a resumed run needs no scheduler state.

/// Peak rate `peak`, `warmup` warm-up steps, `total` steps, floor `min_ratio · peak`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmupCosine {
    pub peak: f64,
    pub warmup: u64,
    pub total: u64,
    pub min_ratio: f64,
}

impl WarmupCosine {
    /// The factor (of the peak) at optimiser step `step` (0-based): `(step + 1) / warmup` during warm-up, then
    /// `min + (1 - min) (1 + cos(π p)) / 2` with `p` the progress through the remaining steps.
    pub fn factor(&self, step: u64) -> f64 {
        if step < self.warmup {
            return (step + 1) as f64 / self.warmup as f64;
        }
        let decay = self.total.saturating_sub(self.warmup).max(1);
        let progress = ((step - self.warmup) as f64 / decay as f64).min(1.0);
        self.min_ratio + (1.0 - self.min_ratio) * 0.5 * (1.0 + (std::f64::consts::PI * progress).cos())
    }

    pub fn rate(&self, step: u64) -> f64 {
        self.peak * self.factor(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warms_up_then_decays_to_the_floor() {
        let s = WarmupCosine { peak: 1e-3, warmup: 10, total: 110, min_ratio: 0.1 };
        assert!((s.rate(0) - 1e-4).abs() < 1e-12 && (s.rate(9) - 1e-3).abs() < 1e-12);
        assert!((s.rate(10) - 1e-3).abs() < 1e-12);
        assert!((s.rate(60) - 1e-3 * 0.55).abs() < 1e-9, "{}", s.rate(60));
        assert!((s.rate(110) - 1e-4).abs() < 1e-12 && (s.rate(500) - 1e-4).abs() < 1e-12);
        let rates: Vec<f64> = (10..110).map(|k| s.rate(k)).collect();
        assert!(rates.windows(2).all(|w| w[1] <= w[0]));
        // No warm-up.
        let s = WarmupCosine { peak: 2.0, warmup: 0, total: 4, min_ratio: 0.0 };
        assert_eq!(s.rate(0), 2.0);
    }
}
