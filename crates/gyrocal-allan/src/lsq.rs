//! Small dense weighted least squares (Householder QR on column-scaled data) and an exact
//! non-negative least squares for a handful of unknowns (best feasible subset).

#![allow(clippy::needless_range_loop)] // dense matrix code reads best with indices

/// Solution of a weighted least-squares problem.
#[derive(Debug, Clone)]
pub(crate) struct Solution {
    pub coef: Vec<f64>,
    /// Covariance of the coefficients, (AᵀWA)⁻¹ (unscaled by the residual).
    pub cov: Vec<Vec<f64>>,
    /// Weighted sum of squared residuals.
    pub ssr: f64,
}

/// Minimises Σ wᵢ (bᵢ − Σⱼ aᵢⱼ cⱼ)² over the columns `cols` of `a`; `None` if rank-deficient.
pub(crate) fn wls(a: &[Vec<f64>], b: &[f64], w: &[f64], cols: &[usize]) -> Option<Solution> {
    let n = b.len();
    let k = cols.len();
    if k == 0 || n < k {
        return None;
    }
    // weighted, column-scaled design
    let mut m: Vec<Vec<f64>> = (0..n)
        .map(|i| cols.iter().map(|&j| a[i][j] * w[i].sqrt()).collect())
        .collect();
    let mut y: Vec<f64> = (0..n).map(|i| b[i] * w[i].sqrt()).collect();
    let mut scale = vec![0.0; k];
    for (j, s) in scale.iter_mut().enumerate() {
        *s = (0..n).map(|i| m[i][j] * m[i][j]).sum::<f64>().sqrt();
        if !(*s > 0.0 && s.is_finite()) {
            return None;
        }
        for row in m.iter_mut() {
            row[j] /= *s;
        }
    }
    // Householder QR
    for j in 0..k {
        let norm = (j..n).map(|i| m[i][j] * m[i][j]).sum::<f64>().sqrt();
        if norm < 1e-13 {
            return None;
        }
        let alpha = if m[j][j] > 0.0 { -norm } else { norm };
        let mut v: Vec<f64> = (j..n).map(|i| m[i][j]).collect();
        v[0] -= alpha;
        let vnorm2: f64 = v.iter().map(|x| x * x).sum();
        if vnorm2 == 0.0 {
            continue;
        }
        for c in j..k {
            let dot: f64 = (j..n).map(|i| v[i - j] * m[i][c]).sum();
            let f = 2.0 * dot / vnorm2;
            for i in j..n {
                m[i][c] -= f * v[i - j];
            }
        }
        let dot: f64 = (j..n).map(|i| v[i - j] * y[i]).sum();
        let f = 2.0 * dot / vnorm2;
        for i in j..n {
            y[i] -= f * v[i - j];
        }
    }
    // back substitution R z = Qᵀy
    let mut z = vec![0.0; k];
    for j in (0..k).rev() {
        let mut s = y[j];
        for c in j + 1..k {
            s -= m[j][c] * z[c];
        }
        z[j] = s / m[j][j];
    }
    let ssr: f64 = y[k..].iter().map(|v| v * v).sum();
    // R⁻¹
    let mut rinv = vec![vec![0.0; k]; k];
    for j in 0..k {
        rinv[j][j] = 1.0 / m[j][j];
        for i in (0..j).rev() {
            let mut s = 0.0;
            for c in i + 1..=j {
                s += m[i][c] * rinv[c][j];
            }
            rinv[i][j] = -s / m[i][i];
        }
    }
    let mut cov = vec![vec![0.0; k]; k];
    for i in 0..k {
        for j in 0..k {
            let s: f64 = (0..k).map(|c| rinv[i][c] * rinv[j][c]).sum();
            cov[i][j] = s / (scale[i] * scale[j]);
        }
    }
    let coef: Vec<f64> = (0..k).map(|j| z[j] / scale[j]).collect();
    if coef.iter().any(|c| !c.is_finite()) {
        return None;
    }
    Some(Solution { coef, cov, ssr })
}

/// Non-negative weighted least squares over at most ~6 columns: the feasible subset solution with
/// the least residual (exact: the NNLS optimum is the unconstrained optimum on its support).
/// Returns the active set (sorted) and its solution.
pub(crate) fn nnls(
    a: &[Vec<f64>],
    b: &[f64],
    w: &[f64],
    ncols: usize,
    allowed: u32,
) -> Option<(Vec<usize>, Solution)> {
    let mut best: Option<(Vec<usize>, Solution)> = None;
    for mask in 1u32..(1 << ncols) {
        if mask & !allowed != 0 {
            continue; // a column the caller leaves out
        }
        let cols: Vec<usize> = (0..ncols).filter(|j| mask & (1 << j) != 0).collect();
        if cols.len() > b.len() {
            continue;
        }
        if let Some(sol) = wls(a, b, w, &cols)
            && sol.coef.iter().all(|&c| c >= 0.0)
            && best.as_ref().is_none_or(|(_, s)| sol.ssr < s.ssr)
        {
            best = Some((cols, sol));
        }
    }
    best
}
