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

/// A data set as column arrays: what `gyrocal fit` reads a (possibly large) file into.
///
/// Memory is 16 bytes a point (24 with a `volts_std` column), against 64 for a [`Point`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Columns {
    /// Where the data came from (a file name), for messages and reports.
    pub source: Option<String>,
    /// Applied rates, °/s.
    pub rates: Vec<f64>,
    /// Mean gyro outputs, V.
    pub volts: Vec<f64>,
    /// The σ of each point as [`Point::sigma`] computes it, NaN where a point has none;
    /// `None` when the source has no `volts_std` column.
    pub sigmas: Option<Vec<f64>>,
    /// The line of the last data row, when the data came from a file.
    pub last_line: Option<u64>,
}

impl Columns {
    /// The columns of a [`Dataset`].
    pub fn from_dataset(data: &Dataset) -> Self {
        let any = data.points.iter().any(|p| p.volts_std.is_some());
        Self {
            source: data.source.clone(),
            rates: data.rates(),
            volts: data.volts(),
            sigmas: any.then(|| {
                data.points
                    .iter()
                    .map(|p| p.sigma().unwrap_or(f64::NAN))
                    .collect()
            }),
            last_line: data.last_line(),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.rates.len().min(self.volts.len())
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The per-point σ used for weighting (as [`Dataset::sigmas`]): `Some` only with
    /// [`Weighting::Auto`] and a usable σ on every point.
    pub fn weighting_sigmas(&self, weighting: Weighting) -> Option<&[f64]> {
        match weighting {
            Weighting::Unweighted => None,
            Weighting::Auto => {
                let s = self.sigmas.as_deref()?;
                (!s.is_empty() && s.iter().all(|s| s.is_finite() && *s > 0.0)).then_some(s)
            }
        }
    }
}

/// The distinct rates of a data set, counted once (one sort of a copy of the rates) and
/// reused by every model check, the per-rate summaries and the neuron.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct RateIndex {
    /// Number of points.
    pub points: usize,
    /// The distinct rates, increasing (`-0.0` and `0.0` are one rate).
    pub distinct: Vec<f64>,
    /// Points at each distinct rate.
    pub counts: Vec<u64>,
}

impl RateIndex {
    pub fn new(rates: &[f64]) -> Self {
        let mut v = rates.to_vec();
        v.sort_unstable_by(f64::total_cmp);
        let mut distinct: Vec<f64> = Vec::new();
        let mut counts: Vec<u64> = Vec::new();
        for w in v {
            match distinct.last() {
                Some(&last) if last == w => {
                    if let Some(c) = counts.last_mut() {
                        *c += 1;
                    }
                }
                _ => {
                    distinct.push(w);
                    counts.push(1);
                }
            }
        }
        distinct.shrink_to_fit();
        counts.shrink_to_fit();
        Self {
            points: rates.len(),
            distinct,
            counts,
        }
    }

    /// Number of distinct rates satisfying `keep`.
    pub fn distinct_where(&self, keep: impl Fn(f64) -> bool) -> usize {
        self.distinct.iter().filter(|w| keep(**w)).count()
    }

    /// Index of `rate` (which must be one of the data's rates) in [`RateIndex::distinct`].
    pub fn group(&self, rate: f64) -> usize {
        self.distinct.partition_point(|d| *d < rate)
    }
}
