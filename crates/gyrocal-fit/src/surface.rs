//! The error surface of the linear model over (weight, threshold), for the report's contour plot.

use serde::{Deserialize, Serialize};

use crate::data::Dataset;

/// Sum of squared residuals of `D = threshold + weight·ω` on a regular grid.
///
/// `sse[i][j]` is the SSE (V², unweighted) at `thresholds[i]` and `weights[j]`: rows follow the
/// threshold axis, columns the weight axis, as a contour plot with the weight on x reads them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorSurface {
    /// Weight (scale factor) axis, V/(°/s), increasing.
    pub weights: Vec<f64>,
    /// Threshold (bias) axis, V, increasing.
    pub thresholds: Vec<f64>,
    /// SSE values, V²; `sse[i][j]` at `(weights[j], thresholds[i])`.
    pub sse: Vec<Vec<f64>>,
    /// Weight at the centre of the grid (the least-squares optimum), V/(°/s).
    pub center_weight: f64,
    /// Threshold at the centre of the grid, V.
    pub center_threshold: f64,
    /// SSE at the centre, V².
    pub center_sse: f64,
}

impl ErrorSurface {
    /// Evaluates the SSE on a `size × size` grid centred on `(weight, threshold)` with the given
    /// half-widths. `size` is made odd (so the centre is a grid point) and at least 3.
    ///
    /// One pass over the data, then the grid in closed form (see `SseForm`).
    pub fn grid(
        data: &Dataset,
        weight: f64,
        threshold: f64,
        half_width_weight: f64,
        half_width_threshold: f64,
        size: usize,
    ) -> Self {
        let rates = data.rates();
        let volts = data.volts();
        Self::grid_columns(
            &rates,
            &volts,
            weight,
            threshold,
            half_width_weight,
            half_width_threshold,
            size,
        )
    }

    /// [`ErrorSurface::grid`] on column arrays.
    pub(crate) fn grid_columns(
        rates: &[f64],
        volts: &[f64],
        weight: f64,
        threshold: f64,
        half_width_weight: f64,
        half_width_threshold: f64,
        size: usize,
    ) -> Self {
        let size = size.max(3) | 1;
        let axis = |c: f64, h: f64| -> Vec<f64> {
            let m = (size / 2) as f64;
            (0..size).map(|k| c + h * (k as f64 - m) / m).collect()
        };
        let weights = axis(weight, half_width_weight);
        let thresholds = axis(threshold, half_width_threshold);
        let form = SseForm::new(rates, volts, None, weight, threshold);
        let sse = thresholds
            .iter()
            .map(|&t| weights.iter().map(|&w| form.at(w, t)).collect())
            .collect();
        Self {
            center_sse: form.srr,
            weights,
            thresholds,
            sse,
            center_weight: weight,
            center_threshold: threshold,
        }
    }

    /// A grid around the optimum `(weight, threshold)` sized so the contours are legible:
    /// the weight half-width is 2 % of `|weight|` (or 1e-3 when it is 0), and the threshold
    /// half-width raises the SSE by the same amount along its axis as the weight half-width
    /// does along its own (`h_θ = h_w·sqrt(Σω²/N)`), so the contours are roughly round.
    pub fn around(data: &Dataset, weight: f64, threshold: f64, size: usize) -> Self {
        Self::around_columns(&data.rates(), &data.volts(), weight, threshold, size)
    }

    /// [`ErrorSurface::around`] on column arrays.
    pub(crate) fn around_columns(
        rates: &[f64],
        volts: &[f64],
        weight: f64,
        threshold: f64,
        size: usize,
    ) -> Self {
        let hw = if weight != 0.0 {
            0.02 * weight.abs()
        } else {
            1e-3
        };
        let n = rates.len().max(1) as f64;
        let rms_rate = (rates.iter().map(|w| w * w).sum::<f64>() / n).sqrt();
        let ht = if rms_rate > 0.0 { hw * rms_rate } else { hw };
        Self::grid_columns(rates, volts, weight, threshold, hw, ht, size)
    }
}

/// The sum of squared residuals of the line `y = t + w·x` as a quadratic form in `(w, t)`,
/// from the data's sufficient statistics about a reference line `(w0, t0)`.
///
/// With `r_i = y_i − (t0 + w0·x_i)`, `dw = w − w0`, `dt = t − t0` and weights `u_i` (1 when
/// unweighted):
///
/// ```text
/// Σ u (y − t − w·x)² = Σur² − 2·dw·Σurx − 2·dt·Σur + dw²·Σux² + 2·dw·dt·Σux + dt²·Σu
/// ```
///
/// exactly (up to rounding). The statistics are taken about the reference rather than as the
/// raw `Σy², Σxy, ...`: near the optimum the raw form subtracts numbers about `Σy²/SSE`
/// (10⁹ and more on a good gyro) times larger than the result, while here `Σur²` is the SSE at
/// the reference, summed directly, and the other terms are small corrections. One pass over
/// the data, then any number of evaluations at O(1) each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SseForm {
    pub w0: f64,
    pub t0: f64,
    pub srr: f64,
    pub srx: f64,
    pub sr: f64,
    pub sxx: f64,
    pub sx: f64,
    pub s1: f64,
}

impl SseForm {
    /// The statistics of `(x, y)` with optional weights `u` about `(w0, t0)`.
    pub fn new(x: &[f64], y: &[f64], u: Option<&[f64]>, w0: f64, t0: f64) -> Self {
        let mut f = Self {
            w0,
            t0,
            srr: 0.0,
            srx: 0.0,
            sr: 0.0,
            sxx: 0.0,
            sx: 0.0,
            s1: 0.0,
        };
        for (i, (&x, &y)) in x.iter().zip(y).enumerate() {
            let u = u.map_or(1.0, |u| u[i]);
            f.add(x, y, u);
        }
        f
    }

    /// Adds one point.
    #[inline]
    pub fn add(&mut self, x: f64, y: f64, u: f64) {
        let r = y - (self.t0 + self.w0 * x);
        // `r.powi(2)`, not `r * r`: the centre's SSE is then bit-identical to the direct sum.
        self.srr += u * r.powi(2);
        self.srx += u * r * x;
        self.sr += u * r;
        self.sxx += u * x * x;
        self.sx += u * x;
        self.s1 += u;
    }

    /// `Σ u (y − t − w·x)²`.
    pub fn at(&self, w: f64, t: f64) -> f64 {
        let dw = w - self.w0;
        let dt = t - self.t0;
        let v = self.srr - 2.0 * dw * self.srx - 2.0 * dt * self.sr
            + dw * dw * self.sxx
            + 2.0 * dw * dt * self.sx
            + dt * dt * self.s1;
        v.max(0.0)
    }

    /// The gradient of `Σ u (y − t − w·x)² / 2` with respect to `(w, t)`.
    pub fn half_gradient(&self, w: f64, t: f64) -> (f64, f64) {
        let dw = w - self.w0;
        let dt = t - self.t0;
        (
            -(self.srx - dw * self.sxx - dt * self.sx),
            -(self.sr - dw * self.sx - dt * self.s1),
        )
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn direct(data: &Dataset, w: f64, t: f64) -> f64 {
        data.points
            .iter()
            .map(|p| (p.volts - (t + w * p.rate_dps)).powi(2))
            .sum()
    }

    #[test]
    fn closed_form_matches_the_direct_sum() {
        // Paper-shaped steps and a noisy many-point set with a bowl-shaped nonlinearity.
        let rates = [
            -20.0, -15.0, -10.0, -7.0, -3.0, -1.0, -0.7, -0.3, -0.1, 0.0, 0.1, 0.3, 0.7, 1.0, 3.0,
            7.0, 10.0, 15.0, 20.0,
        ];
        let paper = Dataset::from_pairs(
            rates
                .iter()
                .map(|&w| (w, 0.0088 + 0.3612 * w + 2e-6 * w * w)),
        );
        let many = Dataset::from_pairs((0..20_000).map(|i| {
            let w = rates[i % rates.len()];
            let noise = 1e-4 * ((i as f64 * 0.618_033_988_7).fract() - 0.5);
            (w, 0.0088 + 0.3612 * w + 2e-6 * w * w + noise)
        }));
        for data in [paper, many] {
            let line =
                crate::fit_least_squares(&data, crate::Model::Linear, Default::default()).unwrap();
            let s = ErrorSurface::around(&data, line.scale_factor, line.bias, 41);
            assert_eq!(s.center_sse, direct(&data, line.scale_factor, line.bias));
            for (i, &t) in s.thresholds.iter().enumerate() {
                for (j, &w) in s.weights.iter().enumerate() {
                    let d = direct(&data, w, t);
                    let c = s.sse[i][j];
                    // Equal to the direct sum up to its own rounding (relative 1e-12 of the
                    // surface's scale, the direct sum's own error being ~N·1e-16).
                    assert!(
                        (c - d).abs() <= 1e-12 * d.max(s.center_sse),
                        "({w}, {t}): closed form {c} direct {d}"
                    );
                }
            }
        }
    }
}
