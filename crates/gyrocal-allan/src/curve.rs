//! A whole stability curve: deviations, EDF, confidence intervals and noise type per τ.

use crate::edf::{ONE_SIGMA_COVERAGE, confidence_interval, edf_greenhall, edf_simple, edf_totdev};
use crate::error::{Error, Result};
use crate::estimators::Estimator;
use crate::noise_id::{NoiseIdMethod, autocorr_noise_id_in};
use crate::phase::{PhaseSource, RateRecord};
use crate::record::Record;
use crate::taus::TauSet;
use crate::terms::{Term, fit_model};

/// A deviation at one τ, without uncertainty (what [`deviations`] returns).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RawPoint {
    /// Averaging time τ = m·τ0 in seconds.
    pub tau_s: f64,
    /// Averaging factor m.
    pub m: usize,
    /// The deviation, in the unit of the rate samples.
    pub deviation: f64,
    /// Number of terms (squared differences) averaged.
    pub n_terms: usize,
}

/// One point of a [`Curve`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Point {
    /// Averaging time τ = m·τ0 in seconds.
    pub tau_s: f64,
    /// Averaging factor m.
    pub m: usize,
    /// The deviation, in the unit of the rate samples.
    pub deviation: f64,
    /// Number of terms (squared differences) averaged.
    pub n_terms: usize,
    /// Equivalent degrees of freedom (Greenhall; NIST SP 1065 Table 7 for TOTDEV).
    pub edf: f64,
    /// 68.27 % (erf(1/√2), allantools' "one sigma") chi-squared interval of the deviation.
    pub ci68: (f64, f64),
    /// 95 % chi-squared interval of the deviation.
    pub ci95: (f64, f64),
    /// Power-law noise exponent α (S_y ∝ f^α: +2 white PM, 0 white FM, −1 flicker FM, −2 random
    /// walk FM) used for the EDF.
    pub noise_alpha: i32,
    /// How `noise_alpha` was obtained.
    pub noise_id_method: NoiseIdMethod,
    /// τ > T/4 (T = N·τ0): computed, but too few independent averages to trust.
    pub beyond_quarter: bool,
}

/// A stability curve of one estimator over a τ set.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Curve {
    /// The estimator.
    pub estimator: Estimator,
    /// Sample interval τ0 of the record, in seconds.
    pub tau0_s: f64,
    /// Number of rate samples N.
    pub n_samples: usize,
    /// The points, by increasing τ.
    pub points: Vec<Point>,
}

/// Minimum record length (rate samples) for any estimator.
pub const MIN_SAMPLES: usize = 3;

fn check_len(n: usize) -> Result<()> {
    if n < MIN_SAMPLES {
        return Err(Error::TooShort {
            what: "a stability curve",
            needed: MIN_SAMPLES,
            got: n,
        });
    }
    Ok(())
}

/// The deviations alone (no noise identification, no EDF): one pass over the record per τ.
/// Points with fewer than two terms are left out, as in allantools. `rec` is a [`Record`] or a
/// [`crate::DiskRecord`] (the same numbers from either).
pub fn deviations<R: RateRecord + ?Sized>(
    rec: &R,
    estimator: Estimator,
    taus: &TauSet,
) -> Result<Vec<RawPoint>> {
    let n = rec.samples();
    check_len(n)?;
    let p = rec.phase();
    let mut pts = Vec::new();
    for m in taus.factors(n, rec.tau0_s()) {
        if let Some((deviation, n_terms)) = estimator.deviation_in(p, m).map_err(Into::into)? {
            pts.push(RawPoint {
                tau_s: m as f64 * rec.tau0_s(),
                m,
                deviation,
                n_terms,
            });
        }
    }
    if pts.is_empty() {
        return Err(Error::NoTaus { n });
    }
    Ok(pts)
}

/// Valid α range of the EDF for an estimator (Greenhall needs α + 2d > 1).
fn clamp_alpha(estimator: Estimator, alpha: i32) -> i32 {
    let lo = 2 - 2 * estimator.difference_order() as i32;
    alpha.clamp(lo, 2)
}

/// EDF of one point; never fails: Greenhall (or Table 7 for TOTDEV), else the simple formulas,
/// else the number of terms.
pub(crate) fn point_edf(
    estimator: Estimator,
    n: usize,
    m: usize,
    alpha: i32,
    n_terms: usize,
) -> f64 {
    let np = n + 1;
    let e = match estimator {
        Estimator::Oadev => edf_greenhall(alpha, 2, m, np, true, false),
        Estimator::Adev => edf_greenhall(alpha, 2, m, np, false, false),
        Estimator::Mdev => edf_greenhall(alpha, 2, m, np, true, true),
        Estimator::Ohdev => edf_greenhall(alpha, 3, m, np, true, false),
        Estimator::Totdev => edf_totdev(n, m, alpha),
    };
    e.or_else(|| edf_simple(np, m, alpha))
        .unwrap_or(n_terms.max(1) as f64)
}

fn alpha_of_term(term: Term) -> i32 {
    match term {
        Term::Quantization => 2,
        Term::AngleRandomWalk => 0,
        Term::BiasInstability => -1,
        Term::RateRandomWalk | Term::RateRamp => -2,
    }
}

/// Builds full points (noise id, EDF, intervals) from raw deviations. `phase` is the record's
/// prefix sums when available (for the autocorrelation noise id), else the model fallback is used.
pub(crate) fn complete<S: PhaseSource + ?Sized>(
    estimator: Estimator,
    tau0_s: f64,
    n: usize,
    raw: &[RawPoint],
    phase: Option<&S>,
) -> std::result::Result<Vec<Point>, S::Error> {
    let dmax = estimator.difference_order();
    let mut ids: Vec<Option<i32>> = Vec::with_capacity(raw.len());
    for r in raw {
        let id = match phase {
            Some(x) => autocorr_noise_id_in(x, r.m, dmax)?,
            None => None,
        };
        ids.push(id.map(|id| clamp_alpha(estimator, id.alpha)));
    }
    let mut alphas: Vec<(i32, NoiseIdMethod)> = ids
        .iter()
        .map(|a| (a.unwrap_or(0), NoiseIdMethod::Lag1Autocorrelation))
        .collect();
    if ids.iter().any(Option::is_none) {
        let t_quarter = n as f64 * tau0_s / 4.0;
        let prov: Vec<(f64, f64, f64)> = raw
            .iter()
            .zip(&alphas)
            .filter(|(r, _)| r.tau_s <= t_quarter || raw.len() < 6)
            .map(|(r, (a, _))| {
                (
                    r.tau_s,
                    r.deviation,
                    point_edf(estimator, n, r.m, *a, r.n_terms),
                )
            })
            .collect();
        let model = fit_model(&prov);
        for (i, id) in ids.iter().enumerate() {
            if id.is_some() {
                continue;
            }
            let tau = raw[i].tau_s;
            alphas[i] = if let Some(term) = model.as_ref().and_then(|f| f.dominant_term(tau)) {
                (
                    clamp_alpha(estimator, alpha_of_term(term)),
                    NoiseIdMethod::ModelDominantTerm,
                )
            } else if let Some(j) = (0..raw.len())
                .filter(|&j| ids[j].is_some())
                .min_by(|&a, &b| {
                    let da = (raw[a].tau_s / tau).ln().abs();
                    let db = (raw[b].tau_s / tau).ln().abs();
                    da.total_cmp(&db)
                })
            {
                (ids[j].unwrap_or(0), NoiseIdMethod::NearestIdentified)
            } else {
                (clamp_alpha(estimator, 0), NoiseIdMethod::AssumedWhiteFm)
            };
        }
    }
    let t = n as f64 * tau0_s;
    Ok(raw
        .iter()
        .zip(alphas)
        .map(|(r, (alpha, method))| {
            let edf = point_edf(estimator, n, r.m, alpha, r.n_terms);
            let nan = (f64::NAN, f64::NAN);
            Point {
                tau_s: r.tau_s,
                m: r.m,
                deviation: r.deviation,
                n_terms: r.n_terms,
                edf,
                ci68: confidence_interval(r.deviation, edf, ONE_SIGMA_COVERAGE).unwrap_or(nan),
                ci95: confidence_interval(r.deviation, edf, 0.95).unwrap_or(nan),
                noise_alpha: alpha,
                noise_id_method: method,
                beyond_quarter: r.tau_s > t / 4.0,
            }
        })
        .collect())
}

/// The full curve of `estimator` over `taus` for a record: a [`Record`] in memory or a
/// [`crate::DiskRecord`] in a file, the same numbers from either.
pub fn compute_record<R: RateRecord + ?Sized>(
    rec: &R,
    estimator: Estimator,
    taus: &TauSet,
) -> Result<Curve> {
    let raw = deviations(rec, estimator, taus)?;
    let points = complete(
        estimator,
        rec.tau0_s(),
        rec.samples(),
        &raw,
        Some(rec.phase()),
    )
    .map_err(Into::into)?;
    Ok(Curve {
        estimator,
        tau0_s: rec.tau0_s(),
        n_samples: rec.samples(),
        points,
    })
}

/// The full curve for rate samples `y` taken every `tau0_s` seconds (copies `y` once into a
/// [`Record`]; use [`Record::from_vec`] and [`compute_record`] to avoid the copy).
pub fn compute(y: &[f64], tau0_s: f64, estimator: Estimator, taus: &TauSet) -> Result<Curve> {
    let rec = Record::from_slice(y, tau0_s)?;
    compute_record(&rec, estimator, taus)
}
