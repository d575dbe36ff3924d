//! The measured data: one point per applied rate.

use serde::{Deserialize, Serialize};

/// One calibration point: the applied rate and the mean gyro output at that rate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// Applied input rate, °/s.
    pub rate_dps: f64,
    /// Mean gyro output at that rate, V.
    pub volts: f64,
    /// Standard deviation of the readings at that rate, V (optional).
    ///
    /// With `n` given this is the spread of the `n` individual readings, and the uncertainty of
    /// the mean is `volts_std / sqrt(n)`; without `n` it is taken as the uncertainty of `volts`
    /// itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volts_std: Option<f64>,
    /// Number of readings averaged into `volts` (optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub n: Option<u64>,
    /// Line of the source file the point was read from, for error messages (optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub line: Option<u64>,
}

impl Point {
    /// A point without uncertainty information.
    pub fn new(rate_dps: f64, volts: f64) -> Self {
        Self {
            rate_dps,
            volts,
            volts_std: None,
            n: None,
            line: None,
        }
    }

    /// The standard deviation of `volts` as an estimate of the true mean output:
    /// `volts_std / sqrt(n)` when `n` is known, `volts_std` otherwise, `None` when the point
    /// carries no usable standard deviation (missing, zero, negative or non-finite).
    pub fn sigma(&self) -> Option<f64> {
        let s = self.volts_std?;
        if !(s.is_finite() && s > 0.0) {
            return None;
        }
        match self.n {
            Some(n) if n > 0 => Some(s / (n as f64).sqrt()),
            _ => Some(s),
        }
    }
}

/// How least squares (and the neuron) weight the points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Weighting {
    /// Weight each point by `1/σ²` (σ from [`Point::sigma`]) when *every* point carries a usable
    /// standard deviation; otherwise unweighted.
    #[default]
    Auto,
    /// Every point has the same weight.
    Unweighted,
}

/// A calibration data set: the points of one run, in the order they were measured.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Dataset {
    /// Where the data came from (a file name), for messages and reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// The points.
    pub points: Vec<Point>,
}

impl Dataset {
    /// A data set from `(rate_dps, volts)` pairs, without uncertainties.
    pub fn from_pairs(pairs: impl IntoIterator<Item = (f64, f64)>) -> Self {
        Self {
            source: None,
            points: pairs.into_iter().map(|(w, d)| Point::new(w, d)).collect(),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The rates, °/s.
    pub fn rates(&self) -> Vec<f64> {
        self.points.iter().map(|p| p.rate_dps).collect()
    }

    /// The outputs, V.
    pub fn volts(&self) -> Vec<f64> {
        self.points.iter().map(|p| p.volts).collect()
    }

    /// Number of distinct rates (exact comparison).
    pub fn distinct_rates(&self) -> usize {
        distinct(self.points.iter().map(|p| p.rate_dps))
    }

    /// The line of the last point, when the data came from a file.
    pub fn last_line(&self) -> Option<u64> {
        self.points.iter().filter_map(|p| p.line).max()
    }

    /// The per-point σ used for weighting, or `None` when the fit is unweighted.
    pub fn sigmas(&self, weighting: Weighting) -> Option<Vec<f64>> {
        match weighting {
            Weighting::Unweighted => None,
            Weighting::Auto => {
                if self.points.is_empty() {
                    return None;
                }
                self.points.iter().map(Point::sigma).collect()
            }
        }
    }
}

pub(crate) fn distinct(values: impl Iterator<Item = f64>) -> usize {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.len()
}
