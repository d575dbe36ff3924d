//! The certificate's plots for `gyrocal serve`'s run page (the live view draws with the same
//! code as the report, so a run looks the same in both): the measured output against rate
//! with the least-squares line, its residuals, a drift record's segment means and σ(τ)
//! curve, and a series' temperatures. Each is bounded whatever the run's length: the fit plots take one point per
//! step, the curve one per τ, and the temperatures are thinned to at most
//! [`TEMPERATURE_POINTS_MAX`] rows.

use gyrocal_analysis::drift::AllanDocument;
use gyrocal_fit::Analysis;

use crate::ReportError;

/// The most temperature rows drawn (evenly thinned, the first and the last kept).
pub const TEMPERATURE_POINTS_MAX: usize = 600;

/// One row of the temperatures: run clock (s), setpoint, air, gyro (product), °C.
pub type TemperatureRow = (f64, Option<f64>, Option<f64>, Option<f64>);

/// Measured output against rate with the fitted lines (the certificate's `fit.svg`).
pub fn fit_svg(a: &Analysis) -> Result<String, ReportError> {
    crate::plots::fit_plot(a)
}

/// The residuals of every fit against rate (the certificate's `residuals.svg`).
pub fn residuals_svg(a: &Analysis) -> Result<String, ReportError> {
    crate::plots::residuals_plot(a)
}

/// A drift record's segment means `(run clock s, mean V)` against the run clock (the live
/// view's plot while the record runs; the caller bounds the points).
pub fn segments_svg(points: &[(f64, f64)]) -> Result<String, ReportError> {
    crate::plots::live::segments_plot(points)
}

/// A drift record's running σ(τ) while it records, `(τ s, σ V)` (the streaming accumulator's
/// octave points, see `gyrocal_run::live::LiveState::adev_v`).
pub fn running_adev_svg(points: &[(f64, f64)]) -> Result<String, ReportError> {
    crate::plots::live::running_adev_plot(points)
}

/// A drift record's σ(τ) with its confidence intervals (the Allan page's curve).
pub fn allan_svg(doc: &AllanDocument) -> Result<String, ReportError> {
    crate::allan::curve_plot(doc)
}

/// The chamber's setpoint, air and the gyro's temperature through the run (the series page's
/// history), from at most [`TEMPERATURE_POINTS_MAX`] of `rows`.
pub fn temperatures_svg(rows: &[TemperatureRow]) -> Result<String, ReportError> {
    crate::plots::series::history_plot(&thin(rows, TEMPERATURE_POINTS_MAX))
}

/// At most `max` of `rows` (about: every k-th, and the last), evenly over the run.
pub fn thin<T: Copy>(rows: &[T], max: usize) -> Vec<T> {
    if rows.len() <= max || max < 2 {
        return rows.to_vec();
    }
    let every = rows.len().div_ceil(max - 1);
    let mut out: Vec<T> = rows.iter().step_by(every).copied().collect();
    if let Some(last) = rows.last()
        && !(rows.len() - 1).is_multiple_of(every)
    {
        out.push(*last);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_the_first_and_last_and_at_most_max() {
        let rows: Vec<usize> = (0..100_000).collect();
        let t = thin(&rows, 600);
        assert!(t.len() <= 600, "{}", t.len());
        assert!(t.len() >= 500, "{}", t.len());
        assert_eq!(t.first(), Some(&0));
        assert_eq!(t.last(), Some(&99_999));
        assert_eq!(thin(&rows[..10], 600).len(), 10);
    }
}
