//! Statistics of the measured table rate: what the table actually did while the gyro was read.

use serde::{Deserialize, Serialize};

/// Summary of measured-rate samples (deg/s).
///
/// `std` is the sample standard deviation (n − 1 in the denominator), 0 with fewer than two
/// samples. With no samples, `count` is 0 and the other fields are NaN, so an empty record is
/// never mistaken for a table at rest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RateStats {
    /// Number of samples.
    pub count: u64,
    /// Mean measured rate, deg/s.
    pub mean: f64,
    /// Sample standard deviation of the measured rate, deg/s.
    pub std: f64,
    /// Smallest measured rate, deg/s.
    pub min: f64,
    /// Largest measured rate, deg/s.
    pub max: f64,
}

impl RateStats {
    /// The statistics of no samples.
    pub const EMPTY: RateStats = RateStats {
        count: 0,
        mean: f64::NAN,
        std: f64::NAN,
        min: f64::NAN,
        max: f64::NAN,
    };

    /// Statistics of a slice of samples.
    pub fn from_samples(samples: &[f64]) -> Self {
        let mut acc = RateAccumulator::default();
        samples.iter().for_each(|&s| acc.push(s));
        acc.stats()
    }
}

/// Running mean, variance, min and max of rate samples (Welford's update: one pass, no stored
/// samples, numerically stable at 20 deg/s ± 1e-4).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RateAccumulator {
    count: u64,
    mean: f64,
    m2: f64,
    min: f64,
    max: f64,
}

impl RateAccumulator {
    /// Adds one sample. Non-finite samples are ignored (a driver never passes one: replies are
    /// parsed into finite numbers or rejected).
    pub fn push(&mut self, x: f64) {
        if !x.is_finite() {
            return;
        }
        if self.count == 0 {
            self.min = x;
            self.max = x;
        } else {
            self.min = self.min.min(x);
            self.max = self.max.max(x);
        }
        self.count += 1;
        let delta = x - self.mean;
        self.mean += delta / self.count as f64;
        self.m2 += delta * (x - self.mean);
    }

    /// Number of samples so far.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The statistics so far.
    pub fn stats(&self) -> RateStats {
        match self.count {
            0 => RateStats::EMPTY,
            n => RateStats {
                count: n,
                mean: self.mean,
                std: if n > 1 {
                    (self.m2 / (n - 1) as f64).sqrt()
                } else {
                    0.0
                },
                min: self.min,
                max: self.max,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welford_matches_two_pass() {
        let xs = [20.0001, 19.9998, 20.0003, 19.9999, 20.0];
        let s = RateStats::from_samples(&xs);
        let mean = xs.iter().sum::<f64>() / 5.0;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 4.0;
        assert_eq!(s.count, 5);
        assert!((s.mean - mean).abs() < 1e-12);
        assert!((s.std - var.sqrt()).abs() < 1e-12);
        assert_eq!((s.min, s.max), (19.9998, 20.0003));
        assert_eq!(RateStats::from_samples(&[]).count, 0);
        assert!(RateStats::from_samples(&[]).mean.is_nan());
    }
}
