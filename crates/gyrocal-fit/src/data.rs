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

/// Most distinct rates for which data count as a **schedule** (rates that repeat: a plan's
/// steps, the paper's 19 rates): the per-rate summaries and the neuron's online passes then
/// have one entry per distinct rate. Data with more distinct rates (a table's measured rate
/// per reading, a ramp, a sinusoid: nearly every rate distinct) are **continuous**: those
/// summaries are over [`RATE_BINS`] equal-width rate bins instead.
///
/// Why a count and not a ratio of points to rates: the summaries are what is bounded (a
/// table a person reads, a plot, a JSON document of a few hundred kilobytes), and a
/// schedule of more than 200 steps is not a calibration plan anyone runs (the paper's has
/// 19, a whole-turn plan a few dozen); at or below the limit nothing changes from before.
pub const RATE_GROUPS_MAX: usize = 200;

/// Rate bins of continuous data (more than [`RATE_GROUPS_MAX`] distinct rates): the rate
/// range `[min, max]` in this many bins of equal width.
///
/// Why equal width, not quantiles: a bin is then an interval of the rate axis, which is what
/// a residual table or a plot against rate shows (quantile bins would crowd where the data
/// are dense and stretch where they are sparse), finding a point's bin is one multiplication
/// (no sort, which matters at 10^7 points), and the count of points in each bin is reported
/// with it, so an unevenly filled range is visible. Bins with no point are left out. 200
/// bins resolve a ±20 °/s range in 0.2 °/s, finer than any curvature a polynomial model
/// describes, and keep the JSON summaries of five fits near 300 kB.
pub const RATE_BINS: usize = 200;

/// The rate bins of continuous data: `bins` intervals of width `width_dps` from `lo_dps` to
/// `hi_dps` (the smallest and largest rate), `[lo + k·w, lo + (k+1)·w)`, the last one closed.
/// In JSON: `{"bins": 200, "lo_dps": -20.0, "hi_dps": 20.0, "width_dps": 0.2, "rule": "..."}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RateBins {
    /// Number of bins ([`RATE_BINS`]), empty ones included.
    pub bins: usize,
    /// Lower edge of the first bin: the smallest rate, °/s.
    pub lo_dps: f64,
    /// Upper edge of the last bin: the largest rate, °/s.
    pub hi_dps: f64,
    /// Width of a bin, °/s.
    pub width_dps: f64,
    /// Why the data were binned, in words ([`RATE_BINS_RULE`]).
    pub rule: String,
}

/// The rule, in words, as written in [`RateBins::rule`].
pub const RATE_BINS_RULE: &str = "more than 200 distinct rates: continuous data, summarised over 200 equal-width bins of the rate range (a schedule, at most 200 distinct rates, is summarised per rate); every figure over all points (SSE, metrics, covariance) is exact";

impl RateBins {
    fn new(lo: f64, hi: f64) -> Self {
        Self {
            bins: RATE_BINS,
            lo_dps: lo,
            hi_dps: hi,
            width_dps: (hi - lo) / RATE_BINS as f64,
            rule: RATE_BINS_RULE.to_string(),
        }
    }

    /// The bin of `rate` (clamped to the first and last bin).
    #[inline]
    pub fn bin(&self, rate: f64) -> usize {
        let k = (rate - self.lo_dps) / self.width_dps;
        // `as` saturates: NaN and negatives go to 0, the top edge to the last bin.
        (k as usize).min(self.bins - 1)
    }

    /// The edges `[lo, hi]` of bin `k`, °/s.
    pub fn edges(&self, k: usize) -> (f64, f64) {
        let lo = self.lo_dps + k as f64 * self.width_dps;
        let hi = if k + 1 >= self.bins {
            self.hi_dps
        } else {
            self.lo_dps + (k + 1) as f64 * self.width_dps
        };
        (lo, hi)
    }
}

/// How the per-rate summaries group the points (see [`RATE_GROUPS_MAX`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum RateGroups {
    /// A schedule: the distinct rates, increasing (`-0.0` and `0.0` are one rate), and the
    /// points at each.
    Rates { rates: Vec<f64>, counts: Vec<u64> },
    /// Continuous data: equal-width bins, and the points in each.
    Bins { bins: RateBins, counts: Vec<u64> },
}

/// The distinct rates of a data set, counted once (one sort of a copy of the rates) and
/// reused by every model check, the per-rate summaries and the neuron.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RateIndex {
    /// Number of points.
    pub points: usize,
    /// Number of distinct rates (exact comparison, `-0.0` equal to `0.0`).
    pub distinct: usize,
    /// Distinct rates below zero.
    pub negative: usize,
    /// Distinct rates above zero.
    pub positive: usize,
    /// Whether zero is one of the rates.
    pub zero: bool,
    /// The groups of the per-rate summaries and of the neuron's online passes.
    pub groups: RateGroups,
}

impl RateIndex {
    pub fn new(rates: &[f64]) -> Self {
        let mut v = rates.to_vec();
        v.sort_unstable_by(f64::total_cmp);
        let (mut distinct, mut negative, mut positive, mut zero) = (0_usize, 0, 0, false);
        let mut list: Vec<f64> = Vec::new();
        let mut counts: Vec<u64> = Vec::new();
        let mut last: Option<f64> = None;
        for &w in &v {
            if last == Some(w) {
                if distinct <= RATE_GROUPS_MAX
                    && let Some(c) = counts.last_mut()
                {
                    *c += 1;
                }
                continue;
            }
            last = Some(w);
            distinct += 1;
            if w < 0.0 {
                negative += 1;
            } else if w > 0.0 {
                positive += 1;
            } else {
                zero = true;
            }
            if distinct <= RATE_GROUPS_MAX {
                list.push(w);
                counts.push(1);
            }
        }
        let groups = if distinct <= RATE_GROUPS_MAX {
            list.shrink_to_fit();
            counts.shrink_to_fit();
            RateGroups::Rates {
                rates: list,
                counts,
            }
        } else {
            // More than RATE_GROUPS_MAX distinct rates: the range is not a single rate.
            let (lo, hi) = (v[0], v[v.len() - 1]);
            let bins = RateBins::new(lo, hi);
            drop(v);
            let mut counts = vec![0_u64; bins.bins];
            for &w in rates {
                counts[bins.bin(w)] += 1;
            }
            RateGroups::Bins { bins, counts }
        };
        Self {
            points: rates.len(),
            distinct,
            negative,
            positive,
            zero,
            groups,
        }
    }

    /// Distinct rates `≥ 0`.
    pub fn nonnegative(&self) -> usize {
        self.positive + usize::from(self.zero)
    }

    /// Distinct rates `≤ 0`.
    pub fn nonpositive(&self) -> usize {
        self.negative + usize::from(self.zero)
    }

    /// Number of groups (distinct rates, or bins including empty ones).
    pub fn group_count(&self) -> usize {
        match &self.groups {
            RateGroups::Rates { rates, .. } => rates.len(),
            RateGroups::Bins { bins, .. } => bins.bins,
        }
    }

    /// Points in each group.
    pub fn counts(&self) -> &[u64] {
        match &self.groups {
            RateGroups::Rates { counts, .. } | RateGroups::Bins { counts, .. } => counts,
        }
    }

    /// The group of `rate` (which must be one of the data's rates).
    #[inline]
    pub fn group(&self, rate: f64) -> usize {
        match &self.groups {
            RateGroups::Rates { rates, .. } => rates.partition_point(|d| *d < rate),
            RateGroups::Bins { bins, .. } => bins.bin(rate),
        }
    }

    /// The bins, when the data are continuous.
    pub fn bins(&self) -> Option<&RateBins> {
        match &self.groups {
            RateGroups::Rates { .. } => None,
            RateGroups::Bins { bins, .. } => Some(bins),
        }
    }
}
