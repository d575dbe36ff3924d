//! Gyro noise terms (IEEE 952-1997/2020 Annex C) from an Allan-deviation curve of a rate in °/h
//! against τ in seconds, by slope reads and by a weighted fit of the five-term model
//!
//! σ²(τ) = 3Q²/τ² + N²/τ + (2 ln 2/π)B² + K²τ/3 + R²τ²/2.
//!
//! # Units
//! With σ in °/h and τ in s the coefficients come out in mixed units and are converted:
//!
//! | term | model unit | reported unit | conversion | read at |
//! |---|---|---|---|---|
//! | Q quantization | (°/h)·s = °/3600 | arcsec (″) | ×1 (1 (°/h)·s = 1″ = 4.848 µrad) | τ = √3 s |
//! | N angle random walk | (°/h)·√s | °/√h | ÷60 (√s = √h/60) | τ = 1 s |
//! | B bias instability | °/h | °/h | σ_min/√(2 ln 2/π) = σ_min/0.6643 | τ of the minimum |
//! | K rate random walk | (°/h)/√s | °/h/√h | ×60 | τ = 3 s |
//! | R rate ramp | (°/h)/s | °/h² | ×3600 | τ = √2 s |
//!
//! Uncertainties are standard (1σ) uncertainties: for slope reads the relative uncertainty of the
//! curve point nearest the read τ, 1/√(2·edf) (conservative: the other points of the region are
//! correlated with it and add little), combined with the spread of the region's points about
//! the line of that slope (the region is never a pure term: a neighbouring term or the
//! sampling at the shortest τ bends it, which 1/√(2·edf) alone would hide); for the bias instability half the width of the 68 % interval of σ_min; for the
//! fit from the covariance of the weighted least squares (weights 1/(σ⁴(2/edf + 0.1²)): the
//! statistics and a 10 % allowance for the model itself), inflated by the reduced χ² when above
//! 1; a rate ramp is fitted only where the curve shows its +1 slope.

use crate::curve::Curve;
use crate::error::{Error, Result};
use crate::estimators::Estimator;
use crate::lsq::{nnls, wls};
use crate::phase::{BLOCK, PhaseCursor, PhaseSource, RateRecord};
use crate::record::Record;

/// √(2 ln 2 / π) = 0.6643: σ of pure flicker FM relative to B at the flat of the curve.
pub const FLICKER_FLOOR: f64 = 0.664_282_154_428_826_6;

/// A value with its standard uncertainty and unit.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Quantity {
    /// The value.
    pub value: f64,
    /// Standard (1σ) uncertainty, same unit.
    pub uncertainty: f64,
    /// Unit of both.
    pub unit: String,
}

impl Quantity {
    fn new(value: f64, uncertainty: f64, unit: &str) -> Quantity {
        Quantity {
            value,
            uncertainty,
            unit: unit.to_string(),
        }
    }
}

/// The five terms of the gyro model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Term {
    /// Quantization noise Q (slope −1).
    Quantization,
    /// Angle random walk N (slope −½).
    AngleRandomWalk,
    /// Bias instability B (slope 0).
    BiasInstability,
    /// Rate random walk K (slope +½).
    RateRandomWalk,
    /// Rate ramp R (slope +1).
    RateRamp,
}

impl Term {
    /// The five terms by increasing slope.
    pub const ALL: [Term; 5] = [
        Term::Quantization,
        Term::AngleRandomWalk,
        Term::BiasInstability,
        Term::RateRandomWalk,
        Term::RateRamp,
    ];

    /// Nominal log-log slope of σ(τ).
    pub fn slope(self) -> f64 {
        match self {
            Term::Quantization => -1.0,
            Term::AngleRandomWalk => -0.5,
            Term::BiasInstability => 0.0,
            Term::RateRandomWalk => 0.5,
            Term::RateRamp => 1.0,
        }
    }

    /// τ (s) at which σ equals the term's coefficient in model units.
    pub fn read_tau_s(self) -> f64 {
        match self {
            Term::Quantization => 3f64.sqrt(),
            Term::AngleRandomWalk => 1.0,
            Term::BiasInstability => f64::NAN,
            Term::RateRandomWalk => 3.0,
            Term::RateRamp => 2f64.sqrt(),
        }
    }

    /// Reported unit.
    pub fn unit(self) -> &'static str {
        match self {
            Term::Quantization => "arcsec",
            Term::AngleRandomWalk => "deg/sqrt(h)",
            Term::BiasInstability => "deg/h",
            Term::RateRandomWalk => "deg/h/sqrt(h)",
            Term::RateRamp => "deg/h^2",
        }
    }

    /// Factor from the model unit (σ in °/h, τ in s) to the reported unit.
    pub fn unit_factor(self) -> f64 {
        match self {
            Term::Quantization | Term::BiasInstability => 1.0,
            Term::AngleRandomWalk => 1.0 / 60.0,
            Term::RateRandomWalk => 60.0,
            Term::RateRamp => 3600.0,
        }
    }

    /// σ²(τ) = coef·basis(τ) with coef = value²/scale: the basis function and the scale.
    fn basis(self, tau: f64) -> f64 {
        match self {
            Term::Quantization => tau.powi(-2),
            Term::AngleRandomWalk => 1.0 / tau,
            Term::BiasInstability => 1.0,
            Term::RateRandomWalk => tau,
            Term::RateRamp => tau * tau,
        }
    }

    /// Coefficient of the basis per squared term value (in model units).
    fn coef_per_value2(self) -> f64 {
        match self {
            Term::Quantization => 3.0,
            Term::AngleRandomWalk => 1.0,
            Term::BiasInstability => FLICKER_FLOOR * FLICKER_FLOOR,
            Term::RateRandomWalk => 1.0 / 3.0,
            Term::RateRamp => 0.5,
        }
    }
}

/// A term read on the curve where the local slope is close to the term's nominal slope.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SlopeRead {
    /// The term in its reported unit, with its uncertainty.
    pub value: Quantity,
    /// τ (s) at which the fitted fixed-slope line was read.
    pub read_at_tau_s: f64,
    /// τ range (s) of the points used.
    pub tau_range_s: (f64, f64),
    /// Number of points used.
    pub points_used: usize,
    /// True if the read τ lies outside the range of the points (an extrapolation of the line).
    pub extrapolated: bool,
}

/// Bias instability from the minimum of the curve.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BiasInstability {
    /// B = σ_min / 0.6643, °/h.
    pub value: Quantity,
    /// The minimum σ itself, °/h.
    pub sigma_min: Quantity,
    /// τ (s) of the minimum.
    pub tau_min_s: f64,
    /// Local slope around the minimum is within ±0.15 of 0 (a flicker floor, not a mere crossing
    /// of the white and random-walk lines, which would overstate B... or understate it).
    pub flat: bool,
}

/// One coefficient of the fitted model.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FittedTerm {
    /// Which term.
    pub term: Term,
    /// The value in its reported unit with its standard uncertainty. A term held at zero by the
    /// non-negativity constraint has value 0 and, as uncertainty, the 1σ value the term could take
    /// (from the fit that frees it).
    pub value: Quantity,
    /// The non-negativity constraint holds this term at zero.
    pub at_zero: bool,
}

/// The weighted non-negative least-squares fit of the five-term model to σ².
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModelFit {
    /// The five terms, in [`Term::ALL`] order.
    pub terms: Vec<FittedTerm>,
    /// Coefficients c of σ² = Σ c·basis(τ) in model units (σ in the curve's unit, τ in s).
    pub coefficients: [f64; 5],
    /// Weighted residual sum over degrees of freedom (≈ 1 when the model and the EDFs are right).
    pub chi2_reduced: f64,
    /// Points used (those with τ ≤ T/4).
    pub points_used: usize,
}

impl ModelFit {
    /// σ² of the model at τ.
    pub fn variance(&self, tau_s: f64) -> f64 {
        Term::ALL
            .iter()
            .zip(self.coefficients)
            .map(|(t, c)| c * t.basis(tau_s))
            .sum()
    }

    /// The term contributing most to σ² at τ (`None` if the model is zero there).
    pub fn dominant_term(&self, tau_s: f64) -> Option<Term> {
        let (term, v) = Term::ALL
            .iter()
            .zip(self.coefficients)
            .map(|(t, c)| (*t, c * t.basis(tau_s)))
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        (v > 0.0 && v.is_finite()).then_some(term)
    }
}

/// Everything the curve says about the gyro's noise.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NoiseTerms {
    /// The estimator of the curve (the slope reads assume the Allan deviation; with MDEV, OHDEV
    /// or TOTDEV they are indicative only).
    pub estimator: Estimator,
    /// Quantization Q by the slope −1 read.
    pub quantization: Option<SlopeRead>,
    /// Angle random walk N by the slope −½ read.
    pub angle_random_walk: Option<SlopeRead>,
    /// Bias instability from the minimum.
    pub bias_instability: Option<BiasInstability>,
    /// Rate random walk K by the slope +½ read.
    pub rate_random_walk: Option<SlopeRead>,
    /// Rate ramp R by the slope +1 read.
    pub rate_ramp: Option<SlopeRead>,
    /// The weighted five-term fit.
    pub fit: Option<ModelFit>,
    /// What could not be read and why.
    pub notes: Vec<String>,
}

/// Accepted deviation of the local slope from the nominal one.
pub const SLOPE_TOLERANCE: f64 = 0.15;

fn slope_read(pts: &[(f64, f64, f64)], term: Term) -> Option<SlopeRead> {
    let s = term.slope();
    let n = pts.len();
    if n < 2 {
        return None;
    }
    // a point qualifies if a neighbouring pair has a local slope within tolerance
    let mut ok = vec![false; n];
    for i in 0..n - 1 {
        let ls = (pts[i + 1].1 / pts[i].1).ln() / (pts[i + 1].0 / pts[i].0).ln();
        if (ls - s).abs() <= SLOPE_TOLERANCE {
            ok[i] = true;
            ok[i + 1] = true;
        }
    }
    // longest contiguous run of qualifying points
    let (mut best, mut cur) = ((0, 0), (0, 0));
    for (i, &q) in ok.iter().enumerate() {
        if q {
            if cur.1 == 0 {
                cur = (i, 0);
            }
            cur.1 += 1;
            if cur.1 > best.1 {
                best = cur;
            }
        } else {
            cur = (0, 0);
        }
    }
    if best.1 < 2 {
        return None;
    }
    let run = &pts[best.0..best.0 + best.1];
    // equal weights in log space: edf weights would let the shortest τ (huge edf, but where the
    // discrete sampling bends the curve) decide alone
    let logc = run.iter().map(|p| p.1.ln() - s * p.0.ln()).sum::<f64>() / run.len() as f64;
    let tau_r = term.read_tau_s();
    let sigma_r = (logc + s * tau_r.ln()).exp();
    // statistical part, conservative: the relative uncertainty of the single point nearest
    // the read τ (octave points overlap, so their information does not simply add)
    let near = run
        .iter()
        .min_by(|a, b| {
            (a.0 / tau_r)
                .ln()
                .abs()
                .total_cmp(&(b.0 / tau_r).ln().abs())
        })
        .map_or(1.0, |p| p.2);
    let rel_stat = (1.0 / (2.0 * near)).sqrt();
    // and how far the points of the run disagree with one line of that slope (another term
    // bending the curve, the sampling at the shortest τ): the spread of their log intercepts,
    // a relative uncertainty, not divided by √n as the octave points are not independent
    let rel_spread = if run.len() >= 3 {
        let k = run.len() as f64;
        let var = run
            .iter()
            .map(|p| (p.1.ln() - s * p.0.ln() - logc).powi(2))
            .sum::<f64>()
            / (k - 1.0);
        var.sqrt()
    } else {
        0.0
    };
    let rel_u = rel_stat.hypot(rel_spread);
    let value = sigma_r * term.unit_factor();
    let lo = run[0].0;
    let hi = run[run.len() - 1].0;
    Some(SlopeRead {
        value: Quantity::new(value, value * rel_u, term.unit()),
        read_at_tau_s: tau_r,
        tau_range_s: (lo, hi),
        points_used: run.len(),
        extrapolated: tau_r < lo || tau_r > hi,
    })
}

/// Fits σ² = Σ c_k basis_k(τ), c ≥ 0, to points (τ s, σ, edf) with weights edf/(2σ⁴), the σ⁴
/// taken from the model after a first pass (iteratively reweighted, 3 passes). `None` with fewer
/// than two usable points.
pub fn fit_model(points: &[(f64, f64, f64)]) -> Option<ModelFit> {
    fit_model_terms(points, &Term::ALL)
}

/// Relative standard uncertainty of σ² allowed for the five-term model itself, beside the
/// statistical 2/edf: no gyro follows the model exactly (a flicker floor is approximate, terms
/// overlap), and without it the shortest τ, with edf in the thousands, would decide the fit
/// alone and hold every long-τ term at zero.
pub const MODEL_RELATIVE_UNCERTAINTY: f64 = 0.1;

/// The weight of a point with `edf` and model (or measured) variance `var` = σ².
fn weight(edf: f64, var: f64) -> f64 {
    1.0 / (var * var * (2.0 / edf + MODEL_RELATIVE_UNCERTAINTY * MODEL_RELATIVE_UNCERTAINTY))
}

/// [`fit_model`] with only the terms in `terms` free (the others held at zero).
pub fn fit_model_terms(points: &[(f64, f64, f64)], terms: &[Term]) -> Option<ModelFit> {
    let allowed: u32 = Term::ALL
        .iter()
        .enumerate()
        .filter(|(_, t)| terms.contains(t))
        .fold(0, |m, (j, _)| m | (1 << j));
    let pts: Vec<&(f64, f64, f64)> = points
        .iter()
        .filter(|p| {
            p.0 > 0.0
                && p.1 > 0.0
                && p.2 > 0.0
                && p.0.is_finite()
                && p.1.is_finite()
                && p.2.is_finite()
        })
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let a: Vec<Vec<f64>> = pts
        .iter()
        .map(|p| Term::ALL.iter().map(|t| t.basis(p.0)).collect())
        .collect();
    let b: Vec<f64> = pts.iter().map(|p| p.1 * p.1).collect();
    let mut w: Vec<f64> = pts.iter().map(|p| weight(p.2, p.1 * p.1)).collect();
    let mut result = None;
    for _ in 0..3 {
        let (cols, sol) = nnls(&a, &b, &w, 5, allowed)?;
        let mut c = [0.0; 5];
        for (k, &j) in cols.iter().enumerate() {
            c[j] = sol.coef[k];
        }
        for (i, p) in pts.iter().enumerate() {
            let model: f64 = (0..5).map(|j| c[j] * a[i][j]).sum();
            let v = if model > 0.0 { model } else { p.1 * p.1 };
            w[i] = weight(p.2, v);
        }
        result = Some((cols, sol, c));
    }
    let (cols, sol, c) = result?;
    let dof = pts.len().saturating_sub(cols.len());
    let chi2_reduced = if dof > 0 {
        sol.ssr / dof as f64
    } else {
        f64::NAN
    };
    let inflate = if chi2_reduced.is_finite() {
        chi2_reduced.max(1.0)
    } else {
        1.0
    };
    let terms = Term::ALL
        .iter()
        .enumerate()
        .map(|(j, &term)| {
            let k = term.coef_per_value2();
            let f = term.unit_factor();
            if let Some(pos) = cols.iter().position(|&cj| cj == j) {
                let cj = c[j];
                let u_c = (sol.cov[pos][pos] * inflate).sqrt();
                let x = (cj / k).sqrt();
                let u_x = if x > 0.0 {
                    u_c / (2.0 * k * x)
                } else {
                    (u_c / k).sqrt()
                };
                FittedTerm {
                    term,
                    value: Quantity::new(x * f, u_x * f, term.unit()),
                    at_zero: false,
                }
            } else {
                // free this term alongside the active ones to see how large it could be
                let mut c2 = cols.clone();
                c2.push(j);
                c2.sort_unstable();
                let u = wls(&a, &b, &w, &c2)
                    .and_then(|s| {
                        c2.iter()
                            .position(|&cj| cj == j)
                            .map(|p| (s.cov[p][p] * inflate).sqrt())
                    })
                    .map(|u_c| (u_c / k).sqrt())
                    .unwrap_or(f64::NAN);
                FittedTerm {
                    term,
                    value: Quantity::new(0.0, u * f, term.unit()),
                    at_zero: true,
                }
            }
        })
        .collect();
    Some(ModelFit {
        terms,
        coefficients: c,
        chi2_reduced,
        points_used: pts.len(),
    })
}

/// The noise terms of a curve of a gyro's rate in °/h (τ in s). Never fails: what cannot be read
/// is `None` with a note. Points beyond T/4 are left out of the reads and the fit.
pub fn noise_terms(curve: &Curve) -> NoiseTerms {
    let pts: Vec<(f64, f64, f64)> = curve
        .points
        .iter()
        .filter(|p| !p.beyond_quarter && p.deviation > 0.0 && p.deviation.is_finite())
        .map(|p| (p.tau_s, p.deviation, p.edf))
        .collect();
    let mut notes = Vec::new();
    if curve.estimator != Estimator::Oadev && curve.estimator != Estimator::Adev {
        notes.push(format!(
            "curve is {}: the IEEE 952 reads assume the Allan deviation",
            curve.estimator.name()
        ));
    }
    let mut read = |term: Term| {
        let r = slope_read(&pts, term);
        if r.is_none() {
            notes.push(format!(
                "{term:?}: no two adjacent points with local slope {:+} ± {SLOPE_TOLERANCE}",
                term.slope()
            ));
        }
        r
    };
    let quantization = read(Term::Quantization);
    let angle_random_walk = read(Term::AngleRandomWalk);
    let rate_random_walk = read(Term::RateRandomWalk);
    let rate_ramp = read(Term::RateRamp);
    let bias_instability = curve
        .points
        .iter()
        .enumerate()
        .filter(|(_, p)| !p.beyond_quarter && p.deviation > 0.0)
        .min_by(|a, b| a.1.deviation.total_cmp(&b.1.deviation))
        .map(|(i, p)| {
            let u = if p.ci68.0.is_finite() && p.ci68.1.is_finite() {
                (p.ci68.1 - p.ci68.0) / 2.0
            } else {
                f64::NAN
            };
            let ps = &curve.points;
            let slope = |a: usize, b: usize| {
                (ps[b].deviation / ps[a].deviation).ln() / (ps[b].tau_s / ps[a].tau_s).ln()
            };
            let left = (i > 0).then(|| slope(i - 1, i));
            let right = (i + 1 < ps.len()).then(|| slope(i, i + 1));
            let flat = [left, right]
                .iter()
                .flatten()
                .any(|s| s.abs() <= SLOPE_TOLERANCE);
            BiasInstability {
                value: Quantity::new(p.deviation / FLICKER_FLOOR, u / FLICKER_FLOOR, "deg/h"),
                sigma_min: Quantity::new(p.deviation, u, "deg/h"),
                tau_min_s: p.tau_s,
                flat,
            }
        });
    // a rate ramp is fitted only where the curve shows its +1 slope: otherwise the few long-τ
    // points, with their wide intervals, let it stand in for the rate random walk
    let fit = if rate_ramp.is_some() {
        fit_model(&pts)
    } else {
        let terms: Vec<Term> = Term::ALL
            .into_iter()
            .filter(|t| *t != Term::RateRamp)
            .collect();
        fit_model_terms(&pts, &terms)
    };
    if fit.is_none() {
        notes.push("five-term fit: fewer than two usable points".into());
    }
    NoiseTerms {
        estimator: curve.estimator,
        quantization,
        angle_random_walk,
        bias_instability,
        rate_random_walk,
        rate_ramp,
        fit,
        notes,
    }
}

/// GJB 2426A-style bias stability: the standard deviation (n − 1) of the means of consecutive
/// windows of `window_s` seconds.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BiasStability {
    /// Window length in seconds (a whole number of samples).
    pub window_s: f64,
    /// Number of windows.
    pub windows: usize,
    /// The standard deviation of the window means, with its uncertainty s/√(2(n−1)).
    pub stability: Quantity,
}

/// Bias (mean) and bias stability of a record.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BiasFigures {
    /// Mean of the record, with its naive standard error (σ/√N; correlated noise makes it larger).
    pub bias: Quantity,
    /// Bias stability over 10 s windows (`None` if fewer than two windows).
    pub stability_10s: Option<BiasStability>,
    /// Bias stability over 100 s windows (`None` if fewer than two windows).
    pub stability_100s: Option<BiasStability>,
}

/// What reading a record's prefix sums can fail with.
type ReadError<R> = <<R as RateRecord>::Phase as PhaseSource>::Error;

/// Bias stability over windows of `window_s` seconds (rounded to whole samples); `unit` is the
/// unit of the record's samples. `rec` is a [`Record`] or a [`crate::DiskRecord`]: the window
/// means are read in two passes (their mean, then the squares), never held.
pub fn bias_stability<R: RateRecord + ?Sized>(
    rec: &R,
    window_s: f64,
    unit: &str,
) -> Result<BiasStability> {
    match stability(rec, window_s, unit) {
        Ok(r) => r,
        Err(e) => Err(e.into()),
    }
}

/// [`bias_stability`], the reading error (outer) apart from the record's own (inner).
fn stability<R: RateRecord + ?Sized>(
    rec: &R,
    window_s: f64,
    unit: &str,
) -> std::result::Result<Result<BiasStability>, ReadError<R>> {
    let w = (window_s / rec.tau0_s()).round();
    if !w.is_finite() || w < 1.0 {
        return Ok(Err(Error::InvalidParameter {
            name: "window_s",
            value: window_s,
            why: "must be at least one sample interval",
        }));
    }
    let w = w as usize;
    let windows = rec.samples() / w;
    if windows < 2 {
        return Ok(Err(Error::TooShort {
            what: "bias stability (two windows)",
            needed: 2 * w,
            got: rec.samples(),
        }));
    }
    let n = windows as f64;
    let mut sum = crate::sum::Neumaier::default();
    for_each_window_mean(rec, w, windows, |m| sum.add(m))?;
    let mu = sum.value() / n;
    // `Iterator::sum` for f64 is a fold from its neutral element (as over Record::window_means)
    let mut ss: f64 = std::iter::empty::<f64>().sum();
    for_each_window_mean(rec, w, windows, |m| ss += (m - mu) * (m - mu))?;
    let s = (ss / (n - 1.0)).sqrt();
    Ok(Ok(BiasStability {
        window_s: w as f64 * rec.tau0_s(),
        windows,
        stability: Quantity::new(s, s / (2.0 * (n - 1.0)).sqrt(), unit),
    }))
}

/// The means of the `windows` consecutive windows of `w` samples, in order, as
/// [`Record::window_means`] computes them.
fn for_each_window_mean<R: RateRecord + ?Sized>(
    rec: &R,
    w: usize,
    windows: usize,
    mut f: impl FnMut(f64),
) -> std::result::Result<(), ReadError<R>> {
    let p = rec.phase();
    let mean = rec.mean();
    let mut buf = vec![0.0; BLOCK.min(windows) + 1];
    let mut done = 0;
    while done < windows {
        let l = BLOCK.min(windows - done);
        p.gather(done * w, w, &mut buf[..l + 1])?;
        for k in 0..l {
            f((buf[k + 1] - buf[k]) / w as f64 + mean);
        }
        done += l;
    }
    Ok(())
}

/// Bias and the 10 s / 100 s bias stabilities of a record in memory in `unit`.
pub fn bias_figures(rec: &Record, unit: &str) -> BiasFigures {
    crate::phase::infallible(figures(rec, unit))
}

/// [`bias_figures`] of a [`Record`] or a [`crate::DiskRecord`] (the same numbers from either);
/// fails only when reading the file fails ([`Error::Io`]).
pub fn bias_figures_in<R: RateRecord + ?Sized>(rec: &R, unit: &str) -> Result<BiasFigures> {
    figures(rec, unit).map_err(Into::into)
}

fn figures<R: RateRecord + ?Sized>(
    rec: &R,
    unit: &str,
) -> std::result::Result<BiasFigures, ReadError<R>> {
    let p = rec.phase();
    let len = rec.samples();
    let n = len as f64;
    // sample standard deviation from the stored deviations from the mean: y_i − ȳ = P[i+1] − P[i]
    let mut ss: f64 = std::iter::empty::<f64>().sum();
    let (mut c0, mut c1) = (p.cursor(0), p.cursor(1));
    let mut done = 0;
    while done < len {
        let l = BLOCK.min(len - done);
        let (a, b) = (c0.next(l)?, c1.next(l)?);
        for k in 0..l {
            ss += (b[k] - a[k]).powi(2);
        }
        done += l;
    }
    let sd = if len > 1 {
        (ss / (n - 1.0)).sqrt()
    } else {
        f64::NAN
    };
    Ok(BiasFigures {
        bias: Quantity::new(rec.mean(), sd / n.sqrt(), unit),
        stability_10s: stability(rec, 10.0, unit)?.ok(),
        stability_100s: stability(rec, 100.0, unit)?.ok(),
    })
}
