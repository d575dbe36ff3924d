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
    pub fn grid(
        data: &Dataset,
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
        let sse_at = |w: f64, t: f64| -> f64 {
            data.points
                .iter()
                .map(|p| (p.volts - (t + w * p.rate_dps)).powi(2))
                .sum()
        };
        let sse = thresholds
            .iter()
            .map(|&t| weights.iter().map(|&w| sse_at(w, t)).collect())
            .collect();
        Self {
            center_sse: sse_at(weight, threshold),
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
        let hw = if weight != 0.0 {
            0.02 * weight.abs()
        } else {
            1e-3
        };
        let n = data.len().max(1) as f64;
        let rms_rate = (data
            .points
            .iter()
            .map(|p| p.rate_dps * p.rate_dps)
            .sum::<f64>()
            / n)
            .sqrt();
        let ht = if rms_rate > 0.0 { hw * rms_rate } else { hw };
        Self::grid(data, weight, threshold, hw, ht, size)
    }
}
