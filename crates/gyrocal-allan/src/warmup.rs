//! The warm-up criterion (IEEE 1431 §12.6), online: readings are fed as they arrive and the
//! detector says when the warm-up is over.
//!
//! The criterion is the one `gyrocal allan` applies to a record afterwards: the readings are
//! cut into consecutive non-overlapping windows of `w` readings; the warm-up is complete when
//! two consecutive window means differ by less than the tolerance, and the warm-up time is the
//! start of that pair (the readings from there on are settled). A maximum ends it regardless.
//!
//! The tolerance is either given (in the readings' unit) or `sigmas` × the white-noise standard
//! deviation of a window mean, σ_A(τ0)/√w, where σ_A(τ0) is the Allan deviation at the reading
//! interval estimated from first differences (√(Σ(y_{i+1} − y_i)²/(2(n − 1)))): a slow drift
//! barely moves first differences, so the estimate is the readings' white noise even during a
//! warm-up. Online it uses the readings seen so far; afterwards, the whole record — the two can
//! differ a little, and both are reported with the tolerance they used.
//!
//! Memory is bounded: a window's running sum, the previous mean and the first-difference sum;
//! the window means kept for a curve are thinned to at most `max_points`.

/// How the tolerance is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tolerance {
    /// A fixed largest change of consecutive window means, in the readings' unit.
    Fixed(f64),
    /// This many white-noise standard deviations of a window mean (σ_A(τ0)/√w), estimated from
    /// the readings so far.
    WhiteSigmas(f64),
}

/// How the warm-up ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// Two consecutive window means agreed within the tolerance.
    Criterion,
    /// The maximum time came first.
    Max,
}

impl Ended {
    /// `criterion` or `max`.
    pub fn as_str(self) -> &'static str {
        match self {
            Ended::Criterion => "criterion",
            Ended::Max => "max",
        }
    }
}

/// The end of the warm-up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmupEnd {
    /// Readings from the start to the end of the warm-up (the first settled reading's index).
    pub samples: u64,
    /// The tolerance in force when it ended, in the readings' unit.
    pub tolerance: f64,
    /// What ended it.
    pub ended_by: Ended,
    /// The change of the last pair of window means compared, in the readings' unit (`None`
    /// before two windows).
    pub last_change: Option<f64>,
}

/// The online detector.
#[derive(Debug, Clone)]
pub struct WarmupDetector {
    window: u64,
    tolerance: Tolerance,
    max_samples: Option<u64>,
    n: u64,
    window_sum: f64,
    window_count: u64,
    previous_mean: Option<f64>,
    last_change: Option<f64>,
    last_value: Option<f64>,
    diff_ss: f64,
    diff_n: u64,
    means: Vec<(u64, f64)>,
    stride: u64,
    max_points: usize,
    end: Option<WarmupEnd>,
}

impl WarmupDetector {
    /// A detector for windows of `window` readings (at least 1), ending at `max_samples`
    /// readings at the latest (`None`: only the criterion ends it); the curve of window means
    /// is thinned to at most `max_points` (at least 2).
    pub fn new(
        window: u64,
        tolerance: Tolerance,
        max_samples: Option<u64>,
        max_points: usize,
    ) -> Self {
        WarmupDetector {
            window: window.max(1),
            tolerance,
            max_samples,
            n: 0,
            window_sum: 0.0,
            window_count: 0,
            previous_mean: None,
            last_change: None,
            last_value: None,
            diff_ss: 0.0,
            diff_n: 0,
            means: Vec::new(),
            stride: 1,
            max_points: max_points.max(2),
            end: None,
        }
    }

    /// Window length, readings.
    pub fn window(&self) -> u64 {
        self.window
    }

    /// Readings fed so far (valid ones; an overload is skipped by the caller).
    pub fn samples(&self) -> u64 {
        self.n
    }

    /// The end, once found.
    pub fn end(&self) -> Option<WarmupEnd> {
        self.end
    }

    /// The change of the last pair of window means compared (`None` before two windows).
    pub fn last_change(&self) -> Option<f64> {
        self.last_change
    }

    /// The tolerance now: the fixed one, or the white-noise estimate from the readings so far
    /// (`None` before two readings).
    pub fn tolerance(&self) -> Option<f64> {
        match self.tolerance {
            Tolerance::Fixed(t) => Some(t),
            Tolerance::WhiteSigmas(k) => (self.diff_n > 0).then(|| {
                let sigma_a = (self.diff_ss / (2.0 * self.diff_n as f64)).sqrt();
                k * sigma_a / (self.window as f64).sqrt()
            }),
        }
    }

    /// The window means so far, `(index of the window's first reading, mean)`, thinned to at
    /// most the detector's `max_points` (every k-th window, k doubling as needed).
    pub fn means(&self) -> &[(u64, f64)] {
        &self.means
    }

    /// Feeds readings; returns the end when it is found by this call (once). Readings after
    /// the end still extend the curve of means, so a display can show the settled level.
    pub fn push(&mut self, values: &[f64]) -> Option<WarmupEnd> {
        let mut found = None;
        for &v in values {
            if !v.is_finite() {
                continue;
            }
            if let Some(last) = self.last_value {
                self.diff_ss += (v - last) * (v - last);
                self.diff_n += 1;
            }
            self.last_value = Some(v);
            self.n += 1;
            self.window_sum += v;
            self.window_count += 1;
            if self.window_count == self.window {
                let mean = self.window_sum / self.window as f64;
                let first = self.n - self.window;
                self.keep_mean(first, mean);
                if let Some(prev) = self.previous_mean {
                    let change = (mean - prev).abs();
                    self.last_change = Some(change);
                    if self.end.is_none()
                        && let Some(tol) = self.tolerance()
                        && change < tol
                    {
                        // settled from the start of the previous window
                        let end = WarmupEnd {
                            samples: first - self.window,
                            tolerance: tol,
                            ended_by: Ended::Criterion,
                            last_change: Some(change),
                        };
                        self.end = Some(end);
                        found = Some(end);
                    }
                }
                self.previous_mean = Some(mean);
                self.window_sum = 0.0;
                self.window_count = 0;
            }
            if self.end.is_none()
                && let Some(max) = self.max_samples
                && self.n >= max
            {
                let end = WarmupEnd {
                    samples: max,
                    tolerance: self.tolerance().unwrap_or(f64::NAN),
                    ended_by: Ended::Max,
                    last_change: self.last_change,
                };
                self.end = Some(end);
                found = Some(end);
            }
        }
        found
    }

    fn keep_mean(&mut self, first: u64, mean: f64) {
        let k = first / self.window;
        if k.is_multiple_of(self.stride) {
            self.means.push((first, mean));
        }
        if self.means.len() > self.max_points {
            self.stride *= 2;
            let stride = self.stride;
            let window = self.window;
            self.means
                .retain(|(i, _)| (i / window).is_multiple_of(stride));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    fn gauss(rng: &mut StdRng) -> f64 {
        StandardNormal.sample(rng)
    }

    /// A bias settling exponentially plus white noise: the detector ends where the offline
    /// rule (first pair of window means within the tolerance) says, wherever the chunks fall.
    #[test]
    fn online_matches_the_rule_applied_afterwards() {
        let mut rng = StdRng::seed_from_u64(7);
        let y: Vec<f64> = (0..20_000)
            .map(|i| 0.5 * (-(i as f64) / 2000.0).exp() + 1e-3 * gauss(&mut rng))
            .collect();
        let w = 200usize;
        let tol = 1e-3;
        let means: Vec<f64> = y
            .chunks_exact(w)
            .map(|c| c.iter().sum::<f64>() / w as f64)
            .collect();
        let k = (1..means.len())
            .find(|&k| (means[k] - means[k - 1]).abs() < tol)
            .expect("settles");
        for chunk in [1usize, 37, 1000, 20_000] {
            let mut d = WarmupDetector::new(w as u64, Tolerance::Fixed(tol), None, 100);
            let mut ends = Vec::new();
            for c in y.chunks(chunk) {
                ends.extend(d.push(c));
            }
            assert_eq!(ends.len(), 1, "ends once");
            assert_eq!(ends[0].samples, ((k - 1) * w) as u64, "chunk {chunk}");
            assert_eq!(ends[0].ended_by, Ended::Criterion);
            assert!(d.means().len() <= 100);
        }
    }

    #[test]
    fn the_maximum_ends_a_warm_up_that_never_settles() {
        // a ramp never settles within a tiny tolerance
        let y: Vec<f64> = (0..5000).map(|i| i as f64 * 1e-3).collect();
        let mut d = WarmupDetector::new(100, Tolerance::Fixed(1e-6), Some(3000), 50);
        let end = d.push(&y).expect("max ends it");
        assert_eq!(end.samples, 3000);
        assert_eq!(end.ended_by, Ended::Max);
    }

    #[test]
    fn the_white_noise_tolerance_follows_the_readings() {
        let mut rng = StdRng::seed_from_u64(3);
        let sigma = 2e-3;
        let y: Vec<f64> = (0..50_000).map(|_| sigma * gauss(&mut rng)).collect();
        let mut d = WarmupDetector::new(100, Tolerance::WhiteSigmas(3.0), None, 50);
        // white noise only: settled within the first windows (a pair of means of white noise
        // differs by less than 3 σ_mean with probability 0.97)
        let end = d.push(&y).expect("settled");
        assert!(end.samples <= 300, "{end:?}");
        let tol = d.tolerance().expect("estimated");
        let want = 3.0 * sigma / 10.0;
        assert!((tol / want - 1.0).abs() < 0.05, "{tol} vs {want}");
    }
}
