//! Least squares by Householder QR of the column-scaled design matrix.

use nalgebra::{DMatrix, DVector};

use crate::data::{Columns, Dataset, RateBins, RateGroups, RateIndex, Weighting};
use crate::error::FitError;
use crate::model::{
    Coefficients, Fit, Method, Model, NeuronTrace, RateResidual, Residual, predict,
};

/// Solution of one polynomial least-squares problem, in original units.
#[derive(Debug, Clone)]
pub(crate) struct PolySolution {
    /// `[k0, k1, ...]`.
    pub coef: Vec<f64>,
    /// Standard errors of `coef`; `None` when `N = p` (no degrees of freedom).
    pub se: Option<Vec<f64>>,
}

/// Rows per Householder QR block: data sets up to this size are factorised in one QR, exactly
/// as before blocks existed; larger ones block by block (below).
pub(crate) const QR_BLOCK: usize = 4096;

/// Fits `y = Σ k_j ω^j` (j = 0..=degree) by least squares to the points whose rate satisfies
/// `keep`.
///
/// The columns are `(ω/ω_max)^j`, so they all lie in [-1, 1] and the cubic stays well
/// conditioned at rates of tens of °/s; the coefficients are mapped back by `k_j = c_j/ω_max^j`.
/// With `sigma`, rows are scaled by `1/σ_i` (weights `1/σ²`). The system is solved with a
/// Householder QR (`R c = Qᵀ b`); the covariance of `c` is `s²·R⁻¹R⁻ᵀ`, with
/// `s² = Σ w_i r_i² / (N − p)` (the residual variance scales the covariance, so the standard
/// errors reflect the scatter actually seen, as numpy's `polyfit(cov=True)` does).
///
/// Memory is bounded: rows are taken [`QR_BLOCK`] at a time, each block stacked under the
/// triangular factor of the rows before it and factorised again (`[R; A_k] = Q_k R'`, the
/// same `R` and `Qᵀb` as one QR of all the rows, up to rounding), so a fit never holds the
/// `N × p` design matrix. `distinct` is the number of distinct kept rates, for the error.
pub(crate) fn solve_poly(
    rates: &[f64],
    volts: &[f64],
    sigma: Option<&[f64]>,
    keep: impl Fn(f64) -> bool,
    degree: usize,
    model: Model,
    distinct: usize,
) -> Result<PolySolution, FitError> {
    let p = degree + 1;
    let mut n = 0_usize;
    let mut scale = 0.0_f64;
    for &w in rates {
        if keep(w) {
            n += 1;
            scale = scale.max(w.abs());
        }
    }
    if n < p {
        return Err(FitError::TooFewPoints {
            model,
            points: n,
            needed: p,
        });
    }
    if scale == 0.0 {
        return Err(FitError::TooFewDistinctRates { distinct: 1 });
    }
    let weight = |i: usize| sigma.map_or(1.0, |s| 1.0 / s[i]);
    let rank_deficient = FitError::RankDeficient {
        model,
        needed: p,
        distinct,
    };
    // (R, first p entries of Qᵀb) of the rows so far.
    let mut acc: Option<(DMatrix<f64>, DVector<f64>)> = None;
    let mut block: Vec<usize> = Vec::with_capacity(QR_BLOCK.min(n));
    let flush = |block: &mut Vec<usize>, acc: &mut Option<(DMatrix<f64>, DVector<f64>)>| {
        let top = if acc.is_some() { p } else { 0 };
        let m = top + block.len();
        let mut a = DMatrix::<f64>::zeros(m, p);
        let mut b = DVector::<f64>::zeros(m);
        if let Some((r, qtb)) = acc.as_ref() {
            a.rows_mut(0, p).copy_from(r);
            b.rows_mut(0, p).copy_from(qtb);
        }
        for (k, &i) in block.iter().enumerate() {
            let row = top + k;
            let x = rates[i] / scale;
            let wi = weight(i);
            let mut xp = wi;
            for j in 0..p {
                a[(row, j)] = xp;
                xp *= x;
            }
            b[row] = volts[i] * wi;
        }
        block.clear();
        let qr = a.qr();
        let r = qr.r();
        let mut qtb = b;
        qr.q_tr_mul(&mut qtb);
        *acc = Some((r, qtb.rows(0, p).into_owned()));
    };
    for (i, &w) in rates.iter().enumerate() {
        if !keep(w) {
            continue;
        }
        block.push(i);
        if block.len() == QR_BLOCK {
            flush(&mut block, &mut acc);
        }
    }
    if !block.is_empty() {
        flush(&mut block, &mut acc);
    }
    let Some((r, rhs)) = acc else {
        return Err(rank_deficient);
    };
    let max_diag = (0..p).fold(0.0_f64, |m, j| m.max(r[(j, j)].abs()));
    if (0..p).any(|j| r[(j, j)].abs() <= 1e-12 * max_diag) {
        return Err(rank_deficient);
    }
    let c = r
        .solve_upper_triangular(&rhs)
        .ok_or_else(|| rank_deficient.clone())?;

    // Weighted residual sum of squares for the covariance scale.
    let mut wsse = 0.0;
    for i in 0..rates.len() {
        if !keep(rates[i]) {
            continue;
        }
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
            .ok_or_else(|| rank_deficient.clone())?;
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

/// One row of a general least-squares problem: the regressors `x`, the observation `y` and the
/// row's weight factor `w` (the row is multiplied by `w`, i.e. a weight `w²` = `1/σ²`).
pub(crate) type DesignRow<const P: usize> = ([f64; P], f64, f64);

/// Solution of a general linear least-squares problem `y ≈ X·k` ([`solve_design`]), in the
/// units of the regressors as given.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DesignSolution<const P: usize> {
    /// The coefficients `k`.
    pub coef: [f64; P],
    /// Covariance of `coef`, `s²·(XᵀWX)⁻¹` with `s² = Σ w²r² / (N − P)`; `None` when `N = P`.
    pub cov: Option<[[f64; P]; P]>,
    /// Weighted residual sum of squares `Σ w²r²`.
    pub wsse: f64,
    /// Rows used.
    pub points: usize,
    /// Residual degrees of freedom `N − P`.
    pub dof: usize,
}

/// Solves a general linear least-squares problem by Householder QR of the column-scaled
/// design matrix, the same way as the polynomial fits: every column is divided by its largest
/// absolute value (so all lie in [-1, 1]), the rows are taken [`QR_BLOCK`] at a time and
/// stacked under the triangular factor of the rows before them, and the covariance comes from
/// the triangular factor, `s²·R⁻¹R⁻ᵀ`, mapped back through the column scales.
///
/// `rows` is called three times (scales, factorisation, residuals) and must yield the same
/// rows each time. Errors, in words, when there are fewer rows than coefficients, a column is
/// zero, or the columns are (numerically) dependent.
pub(crate) fn solve_design<const P: usize, I>(
    rows: impl Fn() -> I,
) -> Result<DesignSolution<P>, String>
where
    I: Iterator<Item = DesignRow<P>>,
{
    let mut n = 0_usize;
    let mut scale = [0.0_f64; P];
    for (x, _, _) in rows() {
        n += 1;
        for j in 0..P {
            scale[j] = scale[j].max(x[j].abs());
        }
    }
    if n < P {
        return Err(format!(
            "{P} coefficients need at least {P} points; there are {n}"
        ));
    }
    if let Some(j) = (0..P).find(|&j| scale[j] == 0.0 || !scale[j].is_finite()) {
        return Err(format!("regressor {j} is zero on every point"));
    }
    let dependent = || "the regressors are linearly dependent on these rates".to_string();
    let mut acc: Option<(DMatrix<f64>, DVector<f64>)> = None;
    let mut block: Vec<DesignRow<P>> = Vec::with_capacity(QR_BLOCK.min(n));
    let flush = |block: &mut Vec<DesignRow<P>>, acc: &mut Option<(DMatrix<f64>, DVector<f64>)>| {
        let top = if acc.is_some() { P } else { 0 };
        let m = top + block.len();
        let mut a = DMatrix::<f64>::zeros(m, P);
        let mut b = DVector::<f64>::zeros(m);
        if let Some((r, qtb)) = acc.as_ref() {
            a.rows_mut(0, P).copy_from(r);
            b.rows_mut(0, P).copy_from(qtb);
        }
        for (k, (x, y, w)) in block.iter().enumerate() {
            for j in 0..P {
                a[(top + k, j)] = x[j] / scale[j] * w;
            }
            b[top + k] = y * w;
        }
        block.clear();
        let qr = a.qr();
        let r = qr.r();
        let mut qtb = b;
        qr.q_tr_mul(&mut qtb);
        *acc = Some((r, qtb.rows(0, P).into_owned()));
    };
    for row in rows() {
        block.push(row);
        if block.len() == QR_BLOCK {
            flush(&mut block, &mut acc);
        }
    }
    if !block.is_empty() {
        flush(&mut block, &mut acc);
    }
    let Some((r, rhs)) = acc else {
        return Err(dependent());
    };
    let max_diag = (0..P).fold(0.0_f64, |m, j| m.max(r[(j, j)].abs()));
    if (0..P).any(|j| r[(j, j)].abs() <= 1e-12 * max_diag) {
        return Err(dependent());
    }
    let c = r.solve_upper_triangular(&rhs).ok_or_else(dependent)?;
    let mut coef = [0.0; P];
    for j in 0..P {
        coef[j] = c[j] / scale[j];
    }
    let mut wsse = 0.0;
    for (x, y, w) in rows() {
        let fitted: f64 = (0..P).map(|j| x[j] * coef[j]).sum();
        let res = (y - fitted) * w;
        wsse += res * res;
    }
    let dof = n - P;
    let cov = if dof > 0 {
        let s2 = wsse / dof as f64;
        let r_inv = r
            .solve_upper_triangular(&DMatrix::<f64>::identity(P, P))
            .ok_or_else(dependent)?;
        let unscaled = &r_inv * r_inv.transpose();
        let mut cov = [[0.0; P]; P];
        for i in 0..P {
            for j in 0..P {
                cov[i][j] = s2 * unscaled[(i, j)] / (scale[i] * scale[j]);
            }
        }
        Some(cov)
    } else {
        None
    };
    if !(coef.iter().all(|c| c.is_finite()) && wsse.is_finite()) {
        return Err("the solution is not finite".to_string());
    }
    Ok(DesignSolution {
        coef,
        cov,
        wsse,
        points: n,
        dof,
    })
}

/// A data set prepared for fitting: its columns, its distinct rates (counted once), the
/// weighting in force, and what the fits record per point.
pub(crate) struct Prepared<'a> {
    pub cols: &'a Columns,
    pub index: RateIndex,
    pub sigmas: Option<&'a [f64]>,
    /// Keep per-point residuals (otherwise per-rate or per-bin summaries).
    pub point_residuals: bool,
    /// Schedule, without per-point residuals: per distinct rate, (sum, min, max) of the
    /// outputs, for the per-rate summaries.
    group_volts: Vec<(f64, f64, f64)>,
    /// Continuous data, without per-point residuals: per bin, (sum of rates, sum of outputs).
    bin_sums: Vec<(f64, f64)>,
    sst: f64,
}

impl<'a> Prepared<'a> {
    /// Checks the values are finite, counts the distinct rates, and (without per-point
    /// residuals) sums the outputs per rate or per bin.
    pub fn new(
        cols: &'a Columns,
        weighting: Weighting,
        point_residuals: bool,
    ) -> Result<Self, FitError> {
        let n = cols.len();
        for (index, (w, d)) in cols.rates[..n].iter().zip(&cols.volts[..n]).enumerate() {
            if !(w.is_finite() && d.is_finite()) {
                return Err(FitError::NonFinite { index });
            }
        }
        let index = RateIndex::new(&cols.rates[..n]);
        let mean = cols.volts[..n].iter().sum::<f64>() / n.max(1) as f64;
        let sst: f64 = cols.volts[..n]
            .iter()
            .map(|v| (v - mean) * (v - mean))
            .sum();
        let mut group_volts = Vec::new();
        let mut bin_sums = Vec::new();
        if !point_residuals {
            match &index.groups {
                RateGroups::Rates { .. } => {
                    group_volts =
                        vec![(0.0, f64::INFINITY, f64::NEG_INFINITY); index.group_count()];
                    for (w, d) in cols.rates[..n].iter().zip(&cols.volts[..n]) {
                        let g = &mut group_volts[index.group(*w)];
                        g.0 += d;
                        g.1 = g.1.min(*d);
                        g.2 = g.2.max(*d);
                    }
                }
                RateGroups::Bins { bins, .. } => {
                    bin_sums = vec![(0.0, 0.0); bins.bins];
                    for (w, d) in cols.rates[..n].iter().zip(&cols.volts[..n]) {
                        let b = &mut bin_sums[bins.bin(*w)];
                        b.0 += w;
                        b.1 += d;
                    }
                }
            }
        }
        Ok(Self {
            cols,
            index,
            sigmas: cols.weighting_sigmas(weighting),
            point_residuals,
            group_volts,
            bin_sums,
            sst,
        })
    }

    pub fn len(&self) -> usize {
        self.cols.len()
    }

    pub fn rates(&self) -> &[f64] {
        &self.cols.rates[..self.len()]
    }

    pub fn volts(&self) -> &[f64] {
        &self.cols.volts[..self.len()]
    }

    /// [`check_rates`] on the precomputed distinct rates.
    pub fn check(&self, model: Model) -> Result<(), FitError> {
        check_index(&self.index, model)
    }
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

/// [`check_rates`] on rates already counted.
pub(crate) fn check_index(index: &RateIndex, model: Model) -> Result<(), FitError> {
    let needed = model.coefficient_count();
    let distinct_all = index.distinct;
    // Distinct rates first: it is the actionable figure (more readings at the same rates
    // cannot determine a polynomial), and fewer points than coefficients implies it.
    if model != Model::Split && distinct_all >= 2 && distinct_all < needed {
        return Err(FitError::RankDeficient {
            model,
            needed,
            distinct: distinct_all,
        });
    }
    if model != Model::Split && index.points < needed {
        return Err(FitError::TooFewPoints {
            model,
            points: index.points,
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
            let pos = index.nonnegative();
            let neg = index.nonpositive();
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
    check_index(&RateIndex::new(rates), model)
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
    let cols = Columns::from_dataset(data);
    let prep = Prepared::new(&cols, weighting, true)?;
    fit_prepared(&prep, model)
}

/// [`fit_least_squares`] on column arrays; fits with more than
/// [`crate::POINT_RESIDUALS_MAX`] points carry per-rate residuals.
pub fn fit_least_squares_columns(
    data: &Columns,
    model: Model,
    weighting: Weighting,
) -> Result<Fit, FitError> {
    let prep = Prepared::new(data, weighting, data.len() <= crate::POINT_RESIDUALS_MAX)?;
    prep.check(model)?;
    fit_prepared(&prep, model)
}

/// [`fit_least_squares`] on prepared data (the caller has checked the model).
pub(crate) fn fit_prepared(prep: &Prepared<'_>, model: Model) -> Result<Fit, FitError> {
    let sigmas = prep.sigmas;
    let rates = prep.rates();
    let volts = prep.volts();
    let (coefficients, std_errors) = match model {
        Model::Split => {
            let side = |keep: fn(f64) -> bool, distinct| -> Result<PolySolution, FitError> {
                solve_poly(rates, volts, sigmas, keep, 1, Model::Split, distinct)
            };
            let pos = side(|w| w >= 0.0, prep.index.nonnegative())?;
            let neg = side(|w| w <= 0.0, prep.index.nonpositive())?;
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
            let sol = solve_poly(
                rates,
                volts,
                sigmas,
                |_| true,
                model.degree(),
                model,
                prep.index.distinct,
            )?;
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
        prep,
        Method::LeastSquares,
        model,
        coefficients,
        std_errors,
        None,
    ))
}

/// Builds a [`Fit`] from coefficients: residuals (per point, or per rate on large data) and
/// the summary figures, in one pass over the points.
pub(crate) fn assemble(
    prep: &Prepared<'_>,
    method: Method,
    model: Model,
    coefficients: Coefficients,
    std_errors: Coefficients,
    neuron: Option<NeuronTrace>,
) -> Fit {
    let n = prep.len();
    let sigmas = prep.sigmas;
    let mut residuals: Vec<Residual> = Vec::new();
    if prep.point_residuals {
        residuals.reserve_exact(n);
    }
    let (mut sse, mut chi2, mut max_abs) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut rate_residuals: Vec<RateResidual> = Vec::new();
    match (&prep.index.groups, prep.point_residuals) {
        (RateGroups::Bins { bins, counts }, false) => {
            // Per bin: (Σ fitted, Σ residual, max |residual|), in the same pass as the totals.
            let mut acc = vec![(0.0_f64, 0.0_f64, 0.0_f64); bins.bins];
            for (i, (&w, &d)) in prep.rates().iter().zip(prep.volts()).enumerate() {
                let fitted = predict(model, &coefficients, w);
                let residual = d - fitted;
                sse += residual * residual;
                if let Some(s) = sigmas {
                    chi2 += (residual / s[i]) * (residual / s[i]);
                }
                max_abs = max_abs.max(residual.abs());
                let a = &mut acc[bins.bin(w)];
                a.0 += fitted;
                a.1 += residual;
                a.2 = a.2.max(residual.abs());
            }
            rate_residuals = bin_residuals(bins, counts, &prep.bin_sums, &acc);
        }
        _ => {
            for (i, (&w, &d)) in prep.rates().iter().zip(prep.volts()).enumerate() {
                let fitted = predict(model, &coefficients, w);
                let residual = d - fitted;
                sse += residual * residual;
                if let Some(s) = sigmas {
                    chi2 += (residual / s[i]) * (residual / s[i]);
                }
                max_abs = max_abs.max(residual.abs());
                if prep.point_residuals {
                    residuals.push(Residual {
                        rate_dps: w,
                        volts: d,
                        fitted,
                        residual,
                    });
                }
            }
            if let (RateGroups::Rates { rates, counts }, false) =
                (&prep.index.groups, prep.point_residuals)
            {
                rate_residuals = rates
                    .iter()
                    .zip(counts)
                    .zip(&prep.group_volts)
                    .map(|((&w, &count), &(sum, min, max))| {
                        let fitted = predict(model, &coefficients, w);
                        let mean_volts = sum / count as f64;
                        RateResidual {
                            rate_dps: w,
                            n: count,
                            mean_volts,
                            fitted,
                            mean_residual: mean_volts - fitted,
                            max_abs_residual: (max - fitted).abs().max((min - fitted).abs()),
                            rate_min_dps: None,
                            rate_max_dps: None,
                        }
                    })
                    .collect();
            }
        }
    }
    let sst = prep.sst;
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
        chi_squared: sigmas.map(|_| chi2),
        rms_residual: (sse / n.max(1) as f64).sqrt(),
        residual_std_error: (n > p).then(|| (sse / (n - p) as f64).sqrt()),
        max_abs_residual: max_abs,
        r_squared: if sst > 0.0 { 1.0 - sse / sst } else { 1.0 },
        residuals,
        rate_residuals,
        passes,
        converged,
        neuron,
    }
}

/// The per-bin summaries of one fit: the bins with points, increasing rate; each one's rate
/// is the mean rate of its points, its fitted value the mean of the fit over its points (so
/// `mean_residual` is the exact mean residual of those points), with the bin's edges.
fn bin_residuals(
    bins: &RateBins,
    counts: &[u64],
    sums: &[(f64, f64)],
    acc: &[(f64, f64, f64)],
) -> Vec<RateResidual> {
    counts
        .iter()
        .zip(sums)
        .zip(acc)
        .enumerate()
        .filter(|(_, ((count, _), _))| **count > 0)
        .map(|(k, ((&count, &(sum_w, sum_d)), &(sum_f, sum_r, max_r)))| {
            let c = count as f64;
            let (lo, hi) = bins.edges(k);
            RateResidual {
                rate_dps: sum_w / c,
                n: count,
                mean_volts: sum_d / c,
                fitted: sum_f / c,
                mean_residual: sum_r / c,
                max_abs_residual: max_r,
                rate_min_dps: Some(lo),
                rate_max_dps: Some(hi),
            }
        })
        .collect()
}

impl Dataset {
    /// Checks that the data can determine `model`: enough points, enough distinct rates, both
    /// turning directions for the split model.
    pub fn check_model(&self, model: Model) -> Result<(), FitError> {
        check(self, model)
    }
}
