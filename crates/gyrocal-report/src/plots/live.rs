//! The live view's own plot (`gyrocal serve`'s run page of a drift record while it runs):
//! drawn in the style of every other plot here.

use plotters::prelude::*;

use super::{Frame, PlotResult, draw, mesh, padded, volt_unit};
use crate::ReportError;
use crate::plots::axis::{LinearAxis, LogAxis};

/// Colour of the segment means.
const MEANS: RGBColor = RGBColor(31, 119, 180);

/// A drift record's segment means `(run clock s, mean V)` against the run clock in hours
/// (a point each, joined by a thin line).
pub(crate) fn segments_plot(points: &[(f64, f64)]) -> Result<String, ReportError> {
    draw("segments.svg", |s| -> PlotResult {
        let root = SVGBackend::with_string(s, (super::WIDTH, super::HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let pts: Vec<(f64, f64)> = points
            .iter()
            .filter(|(t, v)| t.is_finite() && v.is_finite())
            .map(|&(t, v)| (t / 3600.0, v))
            .collect();
        let (fv, unit) = volt_unit(super::max_abs(pts.iter().map(|p| p.1)));
        let pts: Vec<(f64, f64)> = pts.iter().map(|&(t, v)| (t, v * fv)).collect();
        let (x0, x1) = padded(pts.iter().map(|p| p.0));
        let (y0, y1) = padded(pts.iter().map(|p| p.1));
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(y0, y1, 6));
        let frame = Frame::new(72);
        let mut chart = frame
            .builder(&root, "Mean output of each segment", 0)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(
            &mut chart,
            &xa,
            &ya,
            "run clock (h)",
            &format!("mean output ({})", ya.scaled_unit(unit)),
        )?;
        chart.draw_series(LineSeries::new(pts.iter().copied(), MEANS.mix(0.5)))?;
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, MEANS.filled())))?;
        root.present()?;
        Ok(())
    })
}
/// A drift record's running overlapping Allan deviation while it records, `(τ s, σ V)` at the
/// octave τ the streaming accumulator holds (up to 100 s): σ(τ) on decades, a point each,
/// joined, without the intervals and the model the complete record's page adds.
pub(crate) fn running_adev_plot(points: &[(f64, f64)]) -> Result<String, ReportError> {
    draw("running-adev.svg", |s| -> PlotResult {
        let root = SVGBackend::with_string(s, (super::WIDTH, super::HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let pts: Vec<(f64, f64)> = points
            .iter()
            .copied()
            .filter(|&(t, v)| t.is_finite() && t > 0.0 && v.is_finite() && v > 0.0)
            .collect();
        let (fv, unit) = volt_unit(super::max_abs(pts.iter().map(|p| p.1)));
        let pts: Vec<(f64, f64)> = pts.iter().map(|&(t, v)| (t, v * fv)).collect();
        let lo_hi = |f: fn(&(f64, f64)) -> f64| {
            pts.iter()
                .map(f)
                .fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)))
        };
        let ((x0, x1), (y0, y1)) = (lo_hi(|p| p.0), lo_hi(|p| p.1));
        let frame = Frame::new(72);
        let (w, h) = frame.area(0);
        let (xa, ya) = (
            LogAxis::new(x0 / 1.5, x1 * 1.5, w),
            LogAxis::new(y0 / 1.5, y1 * 1.5, h),
        );
        let mut chart = frame
            .builder(
                &root,
                "Running Allan deviation (this session's readings)",
                0,
            )
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(
            &mut chart,
            &xa,
            &ya,
            "averaging time τ (s)",
            &format!("σ(τ) ({unit})"),
        )?;
        chart.draw_series(LineSeries::new(pts.iter().copied(), MEANS.mix(0.5)))?;
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, MEANS.filled())))?;
        root.present()?;
        Ok(())
    })
}
