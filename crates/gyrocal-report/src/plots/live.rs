//! The live view's own plot (`gyrocal serve`'s run page of a drift record while it runs):
//! drawn in the style of every other plot here.

use plotters::prelude::*;

use super::{Frame, PlotResult, draw, mesh, padded, volt_unit};
use crate::ReportError;
use crate::plots::axis::LinearAxis;

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
