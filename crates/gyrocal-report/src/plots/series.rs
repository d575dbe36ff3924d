//! The temperature series' plots: a figure against the gyro's measured temperature with its
//! U as error bars and the chosen model's curve (K(T) as ppm from K at the reference, the
//! bias in °/h), the models' residuals in units of each point's U, and the temperature
//! history of the whole run (setpoint, air, product against time).

use plotters::prelude::*;

use gyrocal_analysis::tempco::TempModel;

use super::legend::{Legend, Swatch, densify};
use super::{Frame, HEIGHT, LinearAxis, PlotResult, WIDTH, draw, mesh, normalised, padded};
use crate::ReportError;

const POINT: RGBColor = RGBColor(31, 119, 180);
const MODEL: RGBColor = RGBColor(255, 127, 14);
const AIR: RGBColor = RGBColor(44, 160, 44);
const PRODUCT: RGBColor = RGBColor(214, 39, 40);

/// One point of a figure against temperature: (T °C, value, U at k = 2), in the plot's unit.
pub(crate) type Measured = (f64, f64, f64);

/// A model's curve on a plot: the model, how its value turns into the plot's unit, and its
/// legend label.
pub(crate) type Curve<'a> = (&'a TempModel, &'a dyn Fn(f64) -> f64, String);

/// A figure against temperature with error bars (U, k = 2) and the model `curve` (the model
/// and how to turn its value into the plot's unit). `name` is the file name for errors.
pub(crate) fn figure_plot(
    name: &str,
    title: &str,
    y_desc: &str,
    pts: &[Measured],
    curve: Option<Curve<'_>>,
) -> Result<String, ReportError> {
    draw(name, |s| -> PlotResult {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let (x0, x1) = padded(pts.iter().map(|p| p.0));
        let line: Vec<(f64, f64)> = curve
            .as_ref()
            .map(|(m, to_unit, _)| {
                (0..=100)
                    .map(|i| {
                        let t = x0 + (x1 - x0) * f64::from(i) / 100.0;
                        (t, to_unit(m.value(t)))
                    })
                    .collect()
            })
            .unwrap_or_default();
        let (y0, y1) = padded(
            pts.iter()
                .flat_map(|p| [p.1 - p.2, p.1 + p.2])
                .chain(line.iter().map(|p| p.1)),
        );
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(y0, y1, 6));
        let mut legend = Legend::new();
        legend.add("measured, U (k = 2)", Swatch::Dot(POINT));
        if let Some((_, _, label)) = &curve {
            legend.add(
                label.clone(),
                Swatch::Line {
                    color: MODEL,
                    width: 2,
                    dashed: false,
                },
            );
        }
        let frame = Frame::new(72);
        let mut data: Vec<(f64, f64)> = pts
            .iter()
            .flat_map(|p| [(p.0, p.1 - p.2), (p.0, p.1 + p.2)])
            .collect();
        data.extend(line.iter().copied());
        let data = densify(&normalised(&data, &xa, &ya), 4);
        let placement = legend.place(&data, frame.area(0));
        let right = Frame::legend_room(&legend, placement);
        let mut chart = frame
            .builder(&root, title, right)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(&mut chart, &xa, &ya, "gyro temperature T (°C)", y_desc)?;
        if !line.is_empty() {
            chart.draw_series(LineSeries::new(line, MODEL.stroke_width(2)))?;
        }
        chart.draw_series(pts.iter().map(|&(t, y, u)| {
            ErrorBar::new_vertical(t, y - u, y, y + u, POINT.stroke_width(2), 10)
        }))?;
        chart.draw_series(
            pts.iter()
                .map(|&(t, y, _)| Circle::new((t, y), 4, POINT.filled())),
        )?;
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

/// The residuals of the models in temperature, each divided by its point's U: within ±1 a
/// point agrees with the model within its own uncertainty. `series`: (label, colour index,
/// points (T, residual/U)).
pub(crate) fn residuals_plot(series: &[(String, Vec<(f64, f64)>)]) -> Result<String, ReportError> {
    draw("series-residuals.svg", |s| -> PlotResult {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let all: Vec<(f64, f64)> = series.iter().flat_map(|s| s.1.iter().copied()).collect();
        let (x0, x1) = padded(all.iter().map(|p| p.0));
        let (y0, y1) = padded(all.iter().map(|p| p.1).chain([-1.2, 1.2]));
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(y0, y1, 6));
        let colors = [POINT, MODEL];
        let mut legend = Legend::new();
        for (i, (label, _)) in series.iter().enumerate() {
            legend.add(label.clone(), Swatch::Dot(colors[i % 2]));
        }
        legend.add(
            "±1: the point's own U",
            Swatch::Line {
                color: RGBColor(120, 120, 120),
                width: 1,
                dashed: true,
            },
        );
        let frame = Frame::new(64);
        let placement = legend.place(&normalised(&all, &xa, &ya), frame.area(0));
        let right = Frame::legend_room(&legend, placement);
        let mut chart = frame
            .builder(&root, "Residuals of the models in temperature", right)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(
            &mut chart,
            &xa,
            &ya,
            "gyro temperature T (°C)",
            "residual / U (k = 2)",
        )?;
        chart.draw_series(LineSeries::new(
            [(xa.lo, 0.0), (xa.hi, 0.0)],
            BLACK.mix(0.6),
        ))?;
        for v in [-1.0, 1.0] {
            chart.draw_series(DashedLineSeries::new(
                [(xa.lo, v), (xa.hi, v)],
                6,
                5,
                RGBColor(120, 120, 120).stroke_width(1),
            ))?;
        }
        for (i, (_, pts)) in series.iter().enumerate() {
            let c = colors[i % 2];
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))?;
        }
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

/// One row of the temperature history: time (s), setpoint, air, product (°C; a missing
/// reading is `None`).
pub(crate) type HistoryRow = (f64, Option<f64>, Option<f64>, Option<f64>);

/// The temperature history of the whole run: the setpoint, the air and the gyro (product)
/// against time, in hours.
pub(crate) fn history_plot(rows: &[HistoryRow]) -> Result<String, ReportError> {
    draw("series-temperatures.svg", |s| -> PlotResult {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let hours = |t: f64| t / 3600.0;
        let pick = |f: fn(&HistoryRow) -> Option<f64>| -> Vec<(f64, f64)> {
            rows.iter()
                .filter_map(|r| f(r).filter(|v| v.is_finite()).map(|v| (hours(r.0), v)))
                .collect()
        };
        let sp = pick(|r| r.1);
        let air = pick(|r| r.2);
        let product = pick(|r| r.3);
        let all: Vec<(f64, f64)> = sp.iter().chain(&air).chain(&product).copied().collect();
        let (x0, x1) = padded(all.iter().map(|p| p.0));
        let (y0, y1) = padded(all.iter().map(|p| p.1));
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(y0, y1, 6));
        let mut legend = Legend::new();
        let entries = [
            ("setpoint", RGBColor(90, 90, 90), &sp, true),
            ("air", AIR, &air, false),
            ("gyro (product)", PRODUCT, &product, false),
        ];
        for (label, color, _, dashed) in &entries {
            legend.add(
                *label,
                Swatch::Line {
                    color: *color,
                    width: 2,
                    dashed: *dashed,
                },
            );
        }
        let frame = Frame::new(64);
        let placement = legend.place(&normalised(&all, &xa, &ya), frame.area(0));
        let right = Frame::legend_room(&legend, placement);
        let mut chart = frame
            .builder(&root, "Temperatures through the run", right)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(&mut chart, &xa, &ya, "run time (h)", "temperature (°C)")?;
        // the setpoint last, on top: a controller that ramps its setpoint (a Watlow's ramp
        // rate) reads back a setpoint the air follows within a few tenths, and drawn under the
        // air it was hidden
        let [setpoint, air_entry, product_entry] = entries;
        for (_, color, pts, dashed) in [air_entry, product_entry, setpoint] {
            if dashed {
                chart.draw_series(DashedLineSeries::new(
                    pts.iter().copied(),
                    8,
                    6,
                    color.stroke_width(2),
                ))?;
            } else {
                chart.draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))?;
            }
        }
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn the_setpoint_is_drawn_over_the_air_it_coincides_with() {
        // a ramped setpoint that the air follows exactly: the dashed setpoint must be the
        // last line drawn, or it is invisible under the air's
        let rows: Vec<HistoryRow> = (0..100)
            .map(|i| {
                let t = f64::from(i) * 60.0;
                let sp = 25.0 - f64::from(i) * 0.4;
                (t, Some(sp), Some(sp), Some(sp + 2.0))
            })
            .collect();
        let svg = history_plot(&rows).unwrap();
        // the first use of each colour is its line (the legend comes after the lines)
        let air = format!("#{:02X}{:02X}{:02X}", AIR.0, AIR.1, AIR.2);
        let air_line = svg.find(&air).unwrap();
        let setpoint_line = svg.find("#5A5A5A").unwrap();
        assert!(
            setpoint_line > air_line,
            "the setpoint is drawn under the air"
        );
    }
}
