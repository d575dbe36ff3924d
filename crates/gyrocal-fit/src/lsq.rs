//! Least squares by Householder QR of the column-scaled design matrix.

use nalgebra::{DMatrix, DVector};

use crate::data::{Dataset, Weighting, distinct};
use crate::error::FitError;
use crate::model::{Coefficients, Fit, Method, Model, NeuronTrace, Residual, predict};

/// Solution of one polynomial least-squares problem, in original units.
#[derive(Debug, Clone)]
pub(crate) struct PolySolution {
    /// `[k0, k1, ...]`.
    pub coef: Vec<f64>,
    /// Standard errors of `coef`; `None` when `N = p` (no degrees of freedom).
    pub se: Option<Vec<f64>>,
}

/// Fits `y = Σ k_j ω^j` (j = 0..=degree) by least squares.
///
/// The columns are `(ω/ω_max)^j`, so they all lie in [-1, 1] and the cubic stays well
/// conditioned at rates of tens of °/s; the coefficients are mapped back by `k_j = c_j/ω_max^j`.
/// With `sigma`, rows are scaled by `1/σ_i` (weights `1/σ²`). The system is solved with a
/// Householder QR (`R c = Qᵀ b`); the covariance of `c` is `s²·R⁻¹R⁻ᵀ`, with
/// `s² = Σ w_i r_i² / (N − p)` (the residual variance scales the covariance, so the standard
/// errors reflect the scatter actually seen, as numpy's `polyfit(cov=True)` does).
pub(crate) fn solve_poly(
    rates: &[f64],
    volts: &[f64],
    sigma: Option<&[f64]>,
    degree: usize,
    model: Model,
) -> Result<PolySolution, FitError> {
    let n = rates.len();
    let p = degree + 1;
    if n < p {
        return Err(FitError::TooFewPoints {
            model,
            points: n,
            needed: p,
        });
    }
    let scale = rates.iter().fold(0.0_f64, |m, w| m.max(w.abs()));
    if scale == 0.0 {
        return Err(FitError::TooFewDistinctRates { distinct: 1 });
    }
    let weight = |i: usize| sigma.map_or(1.0, |s| 1.0 / s[i]);
    let mut a = DMatrix::<f64>::zeros(n, p);
    let mut b = DVector::<f64>::zeros(n);
    for i in 0..n {
        let x = rates[i] / scale;
        let wi = weight(i);
        let mut xp = wi;
        for j in 0..p {
            a[(i, j)] = xp;
            xp *= x;
        }
        b[i] = volts[i] * wi;
    }
    let qr = a.qr();
    let r = qr.r();
    let max_diag = (0..p).fold(0.0_f64, |m, j| m.max(r[(j, j)].abs()));
    if (0..p).any(|j| r[(j, j)].abs() <= 1e-12 * max_diag) {
        return Err(FitError::RankDeficient {
            model,
            needed: p,
            distinct: distinct(rates.iter().copied()),
        });
    }
    let mut qtb = b;
    qr.q_tr_mul(&mut qtb);
    let rhs = qtb.rows(0, p).into_owned();
    let c = r
        .solve_upper_triangular(&rhs)
        .ok_or(FitError::RankDeficient {
            model,
            needed: p,
            distinct: distinct(rates.iter().copied()),
        })?;

    // Weighted residual sum of squares for the covariance scale.
    let mut wsse = 0.0;
    for i in 0..n {
        let x = rates[i] / scale;
        let mut fitted = 0.0;
        for j in (0..p).rev() {
            fitted = fitted * x + c[j];
        }
        let r = (volts[i] - fitted) * weight(i);
        wsse += r * r;
    }

    let se = if n > p {
        let s2 = wsse / (n - p) as f64;
        let r_inv = r
            .solve_upper_triangular(&DMatrix::<f64>::identity(p, p))
            .ok_or(FitError::RankDeficient {
                model,
                needed: p,
                distinct: distinct(rates.iter().copied()),
            })?;
        // cov = s² R⁻¹ R⁻ᵀ; its diagonal is s² times the squared row norms of R⁻¹.
        Some(
            (0..p)
                .map(|j| (s2 * r_inv.row(j).norm_squared()).sqrt() / scale.powi(j as i32))
                .collect(),
        )
    } else {
        None
    };
    let coef = (0..p).map(|j| c[j] / scale.powi(j as i32)).collect();
    Ok(PolySolution { coef, se })
}

/// Checks that `data` can determine `model`, with the errors a user can act on.
pub(crate) fn check(data: &Dataset, model: Model) -> Result<(), FitError> {
    for (index, p) in data.points.iter().enumerate() {
        if !(p.rate_dps.is_finite() && p.volts.is_finite()) {
            return Err(FitError::NonFinite { index });
        }
    }
    check_rates(&data.rates(), model)
}

/// Whether data measured at `rates` (one point per rate, repeats included, in any order) can
/// determine `model`; the error says why not.
///
/// This is the one rule for "can this model be fitted": [`crate::analyze`] skips the models
/// it rejects, and a plan checker calls it on a schedule's rates to warn before a run which
/// models the fit will skip. It needs as many points as the model has coefficients, at least
/// two distinct rates, as many distinct rates as coefficients for the polynomial models, and
/// for the split model at least two distinct rates on each side of zero (zero counts on both).
/// Non-finite rates are the caller's concern (parsed input never holds one).
///
/// ```
/// use gyrocal_fit::{Model, check_rates};
/// assert!(check_rates(&[0.0, 1.0, -1.0, 10.0, -10.0], Model::Cubic).is_ok());
/// let e = check_rates(&[0.0, 1.0, 10.0], Model::Cubic).unwrap_err();
/// assert!(e.to_string().contains("the data have 3"));
/// assert!(check_rates(&[0.0, 1.0, 10.0], Model::Split).is_err());
/// ```
pub fn check_rates(rates: &[f64], model: Model) -> Result<(), FitError> {
    let needed = model.coefficient_count();
    let distinct_all = distinct(rates.iter().copied());
    // Distinct rates first: it is the actionable figure (more readings at the same rates
    // cannot determine a polynomial), and fewer points than coefficients implies it.
    if model != Model::Split && distinct_all >= 2 && distinct_all < needed {
        return Err(FitError::RankDeficient {
            model,
            needed,
            distinct: distinct_all,
        });
    }
    if model != Model::Split && rates.len() < needed {
        return Err(FitError::TooFewPoints {
            model,
            points: rates.len(),
            needed,
        });
    }
    if distinct_all < 2 {
        return Err(FitError::TooFewDistinctRates {
            distinct: distinct_all,
        });
    }
    match model {
        Model::Split => {
            let pos = distinct(rates.iter().copied().filter(|w| *w >= 0.0));
            let neg = distinct(rates.iter().copied().filter(|w| *w <= 0.0));
            if pos < 2 {
                return Err(FitError::SplitNeedsBothSigns {
                    side: "positive",
                    side_sign: ">=",
                    distinct: pos,
                });
            }
            if neg < 2 {
                return Err(FitError::SplitNeedsBothSigns {
                    side: "negative",
                    side_sign: "<=",
                    distinct: neg,
                });
            }
        }
        _ => {
            if distinct_all < needed {
                return Err(FitError::RankDeficient {
                    model,
                    needed,
                    distinct: distinct_all,
                });
            }
        }
    }
    Ok(())
}

/// Fits `model` to `data` by least squares.
///
/// With [`Weighting::Auto`] and a standard deviation on every point, each point is weighted by
/// `1/σ²` with σ from [`crate::Point::sigma`] (the σ of the mean, `volts_std/sqrt(n)`, when `n`
/// is given). Standard errors are scaled by the observed residual variance (see the crate
/// README). Errors when the data cannot determine the model.
pub fn fit_least_squares(
    data: &Dataset,
    model: Model,
    weighting: Weighting,
) -> Result<Fit, FitError> {
    check(data, model)?;
    let sigmas = data.sigmas(weighting);
    let rates = data.rates();
    let volts = data.volts();
    let (coefficients, std_errors) = match model {
        Model::Split => {
            let side = |keep: &dyn Fn(f64) -> bool| -> Result<PolySolution, FitError> {
                let idx: Vec<usize> = (0..rates.len()).filter(|&i| keep(rates[i])).collect();
                let w: Vec<f64> = idx.iter().map(|&i| rates[i]).collect();
                let d: Vec<f64> = idx.iter().map(|&i| volts[i]).collect();
                let s: Option<Vec<f64>> =
                    sigmas.as_ref().map(|s| idx.iter().map(|&i| s[i]).collect());
                solve_poly(&w, &d, s.as_deref(), 1, Model::Split)
            };
            let pos = side(&|w| w >= 0.0)?;
            let neg = side(&|w| w <= 0.0)?;
            let c = Coefficients {
                k0: Some(0.5 * (pos.coef[0] + neg.coef[0])),
                k_pos: Some(pos.coef[1]),
                k_neg: Some(neg.coef[1]),
                k0_pos: Some(pos.coef[0]),
                k0_neg: Some(neg.coef[0]),
                ..Coefficients::default()
            };
            let se = match (&pos.se, &neg.se) {
                (Some(p), Some(n)) => Coefficients {
                    // The two intercepts share the zero-rate points; treating them as
                    // independent is the usual approximation.
                    k0: Some(0.5 * (p[0] * p[0] + n[0] * n[0]).sqrt()),
                    k_pos: Some(p[1]),
                    k_neg: Some(n[1]),
                    k0_pos: Some(p[0]),
                    k0_neg: Some(n[0]),
                    ..Coefficients::default()
                },
                _ => Coefficients::default(),
            };
            (c, se)
        }
        _ => {
            let sol = solve_poly(&rates, &volts, sigmas.as_deref(), model.degree(), model)?;
            let get = |v: &[f64], j: usize| v.get(j).copied();
            let c = Coefficients {
                k0: get(&sol.coef, 0),
                k1: get(&sol.coef, 1),
                k2: get(&sol.coef, 2),
                k3: get(&sol.coef, 3),
                ..Coefficients::default()
            };
            let se = sol
                .se
                .map(|se| Coefficients {
                    k0: get(&se, 0),
                    k1: get(&se, 1),
                    k2: get(&se, 2),
                    k3: get(&se, 3),
                    ..Coefficients::default()
                })
                .unwrap_or_default();
            (c, se)
        }
    };
    Ok(assemble(
        data,
        Method::LeastSquares,
        model,
        coefficients,
        std_errors,
        sigmas.as_deref(),
        None,
    ))
}

/// Builds a [`Fit`] from coefficients: fitted values, residuals and the summary figures.
pub(crate) fn assemble(
    data: &Dataset,
    method: Method,
    model: Model,
    coefficients: Coefficients,
    std_errors: Coefficients,
    sigmas: Option<&[f64]>,
    neuron: Option<NeuronTrace>,
) -> Fit {
    let n = data.len();
    let residuals: Vec<Residual> = data
        .points
        .iter()
        .map(|p| {
            let fitted = predict(model, &coefficients, p.rate_dps);
            Residual {
                rate_dps: p.rate_dps,
                volts: p.volts,
                fitted,
                residual: p.volts - fitted,
            }
        })
        .collect();
    let sse: f64 = residuals.iter().map(|r| r.residual * r.residual).sum();
    let chi_squared = sigmas.map(|s| {
        residuals
            .iter()
            .zip(s)
            .map(|(r, s)| (r.residual / s) * (r.residual / s))
            .sum::<f64>()
    });
    let mean = data.points.iter().map(|p| p.volts).sum::<f64>() / n.max(1) as f64;
    let sst: f64 = data
        .points
        .iter()
        .map(|p| (p.volts - mean) * (p.volts - mean))
        .sum();
    let p = model.coefficient_count();
    let scale_factor = match model {
        Model::Split => {
            0.5 * (coefficients.k_pos.unwrap_or(0.0) + coefficients.k_neg.unwrap_or(0.0))
        }
        _ => coefficients.k1.unwrap_or(0.0),
    };
    let (passes, converged) = match &neuron {
        Some(t) => (
            Some(t.online_passes + t.batch_passes),
            t.status == crate::neuron::NeuronStatus::Converged,
        ),
        None => (None, true),
    };
    Fit {
        method,
        model,
        scale_factor,
        bias: coefficients.k0.unwrap_or(0.0),
        coefficients,
        std_errors,
        weighted: sigmas.is_some(),
        sse,
        chi_squared,
        rms_residual: (sse / n.max(1) as f64).sqrt(),
        residual_std_error: (n > p).then(|| (sse / (n - p) as f64).sqrt()),
        max_abs_residual: residuals.iter().fold(0.0, |m, r| m.max(r.residual.abs())),
        r_squared: if sst > 0.0 { 1.0 - sse / sst } else { 1.0 },
        residuals,
        passes,
        converged,
        neuron,
    }
}

impl Dataset {
    /// Checks that the data can determine `model`: enough points, enough distinct rates, both
    /// turning directions for the split model.
    pub fn check_model(&self, model: Model) -> Result<(), FitError> {
        check(self, model)
    }
}
