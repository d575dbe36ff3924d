//! The plots, drawn with plotters' SVG backend into strings.
//!
//! Every plot is 800×450 (the HTML scales it to the page width) with a title, labelled axes
//! with units, and a legend where there is more than one series. Units are chosen from the
//! magnitude of the data (V/mV/µV, °/s/m°/s/µ°/s) so tick labels stay short.

use std::error::Error;

pub(crate) mod axis;
pub(crate) mod legend;
pub(crate) mod live;
pub(crate) mod series;

use gyrocal_fit::{Analysis, ErrorSurface, Fit, Method, Model};
use plotters::coord::ranged1d::ValueFormatter;
use plotters::prelude::*;

use crate::ReportError;
use crate::input::StepStats;
use axis::{LinearAxis, LogAxis, Ticked};
use legend::{Legend, Placement, Swatch, densify, norm_lin, norm_log};

/// Width of every plot, px.
pub(crate) const WIDTH: u32 = 800;
/// Height of every plot, px.
pub(crate) const HEIGHT: u32 = 450;

const FONT: &str = "sans-serif";
const TITLE_SIZE: u32 = 20;
const LABEL_SIZE: u32 = 14;
const DESC_SIZE: u32 = 16;
const LIGHT: RGBColor = RGBColor(235, 235, 235);
const BOLD: RGBColor = RGBColor(205, 205, 205);

type PlotResult = Result<(), Box<dyn Error>>;

/// Colour of a fit's series (same in every plot).
pub(crate) fn fit_color(method: Method, model: Model) -> RGBColor {
    match (method, model) {
        (Method::Neuron, _) => RGBColor(214, 39, 40),
        (_, Model::Linear) => RGBColor(31, 119, 180),
        (_, Model::Quadratic) => RGBColor(255, 127, 14),
        (_, Model::Cubic) => RGBColor(44, 160, 44),
        (_, Model::Split) => RGBColor(148, 103, 189),
    }
}

/// A fit's name in legends and tables.
pub(crate) fn fit_name(f: &Fit) -> String {
    match f.method {
        Method::Neuron => "neuron (linear)".to_string(),
        Method::LeastSquares => format!("least squares, {}", f.model),
    }
}

/// The axes and grid, styled the same in every plot: `.draw_styled()` in place of `.draw()`.
trait DrawStyled {
    fn draw_styled(&mut self) -> PlotResult;
}

impl<X, Y, XT, YT, DB> DrawStyled for plotters::chart::MeshStyle<'_, '_, X, Y, DB>
where
    X: Ranged<ValueType = XT> + ValueFormatter<XT>,
    Y: Ranged<ValueType = YT> + ValueFormatter<YT>,
    DB: DrawingBackend,
    DB::ErrorType: 'static,
{
    fn draw_styled(&mut self) -> PlotResult {
        self.axis_desc_style((FONT, DESC_SIZE))
            .label_style((FONT, LABEL_SIZE))
            .light_line_style(LIGHT)
            .bold_line_style(BOLD)
            .draw()?;
        Ok(())
    }
}

/// A chart on the axes of [`axis`]: the coordinate type of every plot here.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<Ticked, Ticked>>;

/// An axis of [`axis`], whichever kind: its tick labels.
trait Labels {
    fn label(&self, v: f64) -> String;
}

impl Labels for LinearAxis {
    fn label(&self, v: f64) -> String {
        LinearAxis::label(self, v)
    }
}

impl Labels for LogAxis {
    fn label(&self, v: f64) -> String {
        LogAxis::label(self, v)
    }
}

/// The mesh of a chart: the axes' own tick labels, titles, the shared style.
fn mesh<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    x: &impl Labels,
    y: &impl Labels,
    x_desc: &str,
    y_desc: &str,
) -> PlotResult
where
    DB::ErrorType: 'static,
{
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v| x.label(*v))
        .y_label_formatter(&|v| y.label(*v))
        .draw_styled()
}

/// The layout of a plot's frame, px: what [`Legend::place`] needs before the chart exists
/// (the plotting area is the frame less these).
#[derive(Debug, Clone, Copy)]
struct Frame {
    size: (u32, u32),
    margin: u32,
    caption: u32,
    x_area: u32,
    y_area: u32,
    right_area: u32,
}

impl Frame {
    const fn new(y_area: u32) -> Frame {
        Frame {
            size: (WIDTH, HEIGHT),
            margin: 12,
            caption: 34,
            x_area: 48,
            y_area,
            right_area: 0,
        }
    }

    /// The plotting area (width, height), px, with `right` more px taken on the right.
    fn area(&self, right: u32) -> (f64, f64) {
        (
            f64::from(self.size.0 - 2 * self.margin - self.y_area - self.right_area - right),
            f64::from(self.size.1 - 2 * self.margin - self.caption - self.x_area),
        )
    }

    /// The room a legend placed outside takes.
    fn legend_room(legend: &Legend, placement: Placement) -> u32 {
        match placement {
            Placement::Outside => u32::try_from(legend.width()).unwrap_or(200) + 24,
            Placement::Corner(_) => 0,
        }
    }

    /// A chart builder on `root` with this frame's margins and label areas, `right` px more
    /// on the right.
    fn builder<'a, 'b, DB: DrawingBackend>(
        &self,
        root: &'a DrawingArea<DB, plotters::coord::Shift>,
        caption: &str,
        right: u32,
    ) -> ChartBuilder<'a, 'b, DB> {
        let mut b = ChartBuilder::on(root);
        b.caption(caption, (FONT, TITLE_SIZE))
            .margin(self.margin)
            .margin_right(self.margin + right)
            .x_label_area_size(self.x_area)
            .y_label_area_size(self.y_area);
        if self.right_area > 0 {
            b.right_y_label_area_size(self.right_area);
        }
        b
    }
}

/// Normalised positions of `pts` on the axes `xa`, `ya` (linear), for [`Legend::place`].
fn normalised(pts: &[(f64, f64)], xa: &LinearAxis, ya: &LinearAxis) -> Vec<(f64, f64)> {
    pts.iter()
        .map(|&(x, y)| (norm_lin(x, xa.lo, xa.hi), norm_lin(y, ya.lo, ya.hi)))
        .collect()
}

/// Draws into a string; maps the backend's error to [`ReportError::Plot`] naming the plot.
fn draw(name: &str, f: impl FnOnce(&mut String) -> PlotResult) -> Result<String, ReportError> {
    let mut s = String::new();
    f(&mut s).map_err(|e| ReportError::Plot {
        name: name.to_string(),
        message: e.to_string(),
    })?;
    Ok(s)
}

/// `(factor, unit)` to show volts of this magnitude.
pub(crate) fn volt_unit(max_abs: f64) -> (f64, &'static str) {
    if max_abs >= 0.5 {
        (1.0, "V")
    } else if max_abs >= 5e-4 {
        (1e3, "mV")
    } else {
        (1e6, "µV")
    }
}

/// `(factor, unit)` to show °/s of this magnitude.
fn rate_unit(max_abs: f64) -> (f64, &'static str) {
    if max_abs >= 0.5 {
        (1.0, "°/s")
    } else if max_abs >= 5e-4 {
        (1e3, "m°/s")
    } else {
        (1e6, "µ°/s")
    }
}

/// The range of `values` with 5 % padding (a finite, non-empty range in every case).
fn padded(values: impl IntoIterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() || !hi.is_finite() {
        return (-1.0, 1.0);
    }
    let span = hi - lo;
    if span <= 0.0 {
        let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
        return (lo - d, hi + d);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

fn max_abs(values: impl IntoIterator<Item = f64>) -> f64 {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold(0.0_f64, |m, v| m.max(v.abs()))
}

/// Measured output vs rate with the least-squares and neuron lines and the best model.
pub(crate) fn fit_plot(a: &Analysis) -> Result<String, ReportError> {
    draw("fit.svg", |s| {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let pts: Vec<(f64, f64)> = a
            .fit(Method::LeastSquares, Model::Linear)
            .or_else(|| a.fits.first())
            .map(|f| f.residuals.iter().map(|r| (r.rate_dps, r.volts)).collect())
            .unwrap_or_default();
        let (x0, x1) = padded(pts.iter().map(|p| p.0));
        let (y0, y1) = padded(pts.iter().map(|p| p.1));
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(y0, y1, 6));
        let line = |f: &Fit, n: usize| -> Vec<(f64, f64)> {
            (0..=n)
                .map(|i| {
                    let w = x0 + (x1 - x0) * i as f64 / n as f64;
                    (w, f.predict(w))
                })
                .collect()
        };
        let best = a
            .best_model
            .filter(|m| *m != Model::Linear)
            .and_then(|m| a.fit(Method::LeastSquares, m));
        let ls = a.fit(Method::LeastSquares, Model::Linear);
        let neuron = a.fit(Method::Neuron, Model::Linear);
        let mut legend = Legend::new();
        if let Some(f) = best {
            legend.add(
                format!("best model: least squares, {} (wide line)", f.model),
                Swatch::Line {
                    color: fit_color(f.method, f.model),
                    width: 6,
                    dashed: false,
                },
            );
        }
        if let Some(f) = ls {
            legend.add(
                format!(
                    "least squares: K = {:.6} V/(°/s), K0 = {:.5} V",
                    f.scale_factor, f.bias
                ),
                Swatch::Line {
                    color: fit_color(f.method, f.model),
                    width: 2,
                    dashed: false,
                },
            );
        }
        if let Some(f) = neuron {
            legend.add(
                format!(
                    "neuron: K = {:.6} V/(°/s), K0 = {:.5} V",
                    f.scale_factor, f.bias
                ),
                Swatch::Line {
                    color: fit_color(f.method, f.model),
                    width: 2,
                    dashed: true,
                },
            );
        }
        legend.add("measured (mean output per step)", Swatch::Dot(BLACK));
        let frame = Frame::new(64);
        let mut data = normalised(&pts, &xa, &ya);
        if let Some(f) = ls {
            data.extend(densify(&normalised(&line(f, 2), &xa, &ya), 40));
        }
        let placement = legend.place(&data, frame.area(0));
        let right = Frame::legend_room(&legend, placement);
        let mut chart = frame
            .builder(&root, "Measured output vs rate", right)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(
            &mut chart,
            &xa,
            &ya,
            "input rate ω (°/s)",
            &format!("gyro output D ({})", ya.scaled_unit("V")),
        )?;
        // The best model first, wide and light, so the two lines stay visible on top of it.
        if let Some(f) = best {
            let c = fit_color(f.method, f.model);
            chart.draw_series(LineSeries::new(line(f, 200), c.mix(0.55).stroke_width(6)))?;
        }
        if let Some(f) = ls {
            let c = fit_color(f.method, f.model);
            chart.draw_series(LineSeries::new(line(f, 2), c.stroke_width(2)))?;
        }
        if let Some(f) = neuron {
            let c = fit_color(f.method, f.model);
            chart.draw_series(DashedLineSeries::new(line(f, 2), 8, 6, c.stroke_width(2)))?;
        }
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, BLACK.filled())))?;
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

/// Residuals vs rate of every fit, in volts (left axis, V, mV or µV as its title says) and in
/// °/s equivalent (right axis, residual / K of the least-squares line).
pub(crate) fn residuals_plot(a: &Analysis) -> Result<String, ReportError> {
    draw("residuals.svg", |s| {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let k = a.metrics.scale_factor;
        let all = a
            .fits
            .iter()
            .flat_map(|f| f.residuals.iter().map(|r| r.residual));
        let (fv, vunit) = volt_unit(max_abs(all.clone()));
        let (x0, x1) = padded(
            a.fits
                .iter()
                .flat_map(|f| f.residuals.iter().map(|r| r.rate_dps)),
        );
        let (y0, y1) = padded(all.map(|r| r * fv));
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(y0, y1, 6));
        let runit = vunit.replace('V', "°/s");
        // the right axis: the same heights divided by K (its ends are the left axis's / K)
        let sa = if k > 0.0 && k.is_finite() {
            LinearAxis::new(ya.lo / k, ya.hi / k, 6)
        } else {
            LinearAxis::new(ya.lo, ya.hi, 6)
        };
        let series: Vec<(&Fit, Vec<(f64, f64)>)> = a
            .fits
            .iter()
            .map(|f| {
                let mut pts: Vec<(f64, f64)> = f
                    .residuals
                    .iter()
                    .map(|r| (r.rate_dps, r.residual * fv))
                    .collect();
                pts.sort_by(|p, q| p.0.total_cmp(&q.0));
                (f, pts)
            })
            .collect();
        let mut legend = Legend::new();
        let mut data = Vec::new();
        for (f, pts) in &series {
            let c = fit_color(f.method, f.model);
            legend.add(
                fit_name(f),
                if f.method == Method::Neuron {
                    Swatch::Line {
                        color: c,
                        width: 2,
                        dashed: true,
                    }
                } else {
                    Swatch::Line {
                        color: c,
                        width: 2,
                        dashed: false,
                    }
                },
            );
            data.extend(densify(&normalised(pts, &xa, &ya), 12));
        }
        let mut frame = Frame::new(64);
        frame.right_area = 64;
        let placement = legend.place(&data, frame.area(0));
        let right = Frame::legend_room(&legend, placement);
        let mut chart = frame
            .builder(&root, "Residuals (measured − fitted) vs rate", right)
            .build_cartesian_2d(xa.coord(), ya.coord())?
            .set_secondary_coord(xa.coord(), sa.coord());
        mesh(
            &mut chart,
            &xa,
            &ya,
            "input rate ω (°/s)",
            &format!("residual ({})", ya.scaled_unit(vunit)),
        )?;
        chart
            .configure_secondary_axes()
            .y_desc(format!(
                "residual / K ({} equivalent)",
                sa.scaled_unit(&runit)
            ))
            .y_label_formatter(&|v| sa.label(*v))
            .axis_desc_style((FONT, DESC_SIZE))
            .label_style((FONT, LABEL_SIZE))
            .draw()?;
        chart.draw_series(LineSeries::new(
            [(xa.lo, 0.0), (xa.hi, 0.0)],
            BLACK.mix(0.6),
        ))?;
        for (f, pts) in &series {
            let c = fit_color(f.method, f.model);
            if f.method == Method::Neuron {
                chart.draw_series(DashedLineSeries::new(pts.clone(), 6, 4, c.stroke_width(2)))?;
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, 5, c.stroke_width(2))))?;
            } else {
                chart.draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?;
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))?;
            }
        }
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

/// The neuron's training error per pass (log scale, every decade labelled) with the
/// least-squares minimum SSE.
pub(crate) fn training_plot(neuron: &Fit, ls_sse: Option<f64>) -> Result<String, ReportError> {
    draw("training.svg", |s| {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let trace = neuron.neuron.as_ref();
        let errors: &[f64] = trace.map_or(&[], |t| t.pass_errors.as_slice());
        let n = errors.len().max(1);
        // At most ~2000 points: a line of 100 000 passes would make a megabyte of SVG.
        let step = n.div_ceil(2000).max(1);
        let pts: Vec<(f64, f64)> = errors
            .iter()
            .enumerate()
            .filter(|(i, _)| i % step == 0 || *i + 1 == errors.len())
            .filter(|(_, e)| e.is_finite() && **e > 0.0)
            .map(|(i, e)| ((i + 1) as f64, *e))
            .collect();
        let sse = ls_sse.filter(|v| *v > 0.0 && v.is_finite());
        let positive = pts.iter().map(|p| p.1).chain(sse);
        let (lo, hi) = positive.fold((f64::INFINITY, 0.0_f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        let frame = Frame::new(80);
        let (_, area_h) = frame.area(0);
        let ya = LogAxis::new(lo / 1.2, hi * 1.2, area_h);
        let xa = LinearAxis::new(0.0, n as f64 + 1.0, 8);
        let c = fit_color(Method::Neuron, Model::Linear);
        let b = fit_color(Method::LeastSquares, Model::Linear);
        let g = RGBColor(90, 90, 90);
        let mut legend = Legend::new();
        legend.add(
            "neuron: SSE after each pass",
            Swatch::Line {
                color: c,
                width: 2,
                dashed: false,
            },
        );
        if let Some(sse) = sse {
            legend.add(
                format!(
                    "least-squares minimum SSE = {} V²",
                    gyrocal_fit::display::significant(sse, 5)
                ),
                Swatch::Line {
                    color: b,
                    width: 2,
                    dashed: true,
                },
            );
        }
        let online = trace.filter(|t| t.online_passes > 0 && t.batch_passes > 0);
        if let Some(t) = online {
            legend.add(
                format!(
                    "end of {} online passes; then {} full-batch passes",
                    t.online_passes, t.batch_passes
                ),
                Swatch::Line {
                    color: g,
                    width: 1,
                    dashed: false,
                },
            );
        }
        let data: Vec<(f64, f64)> = pts
            .iter()
            .map(|&(x, y)| (norm_lin(x, xa.lo, xa.hi), norm_log(y, ya.lo, ya.hi)))
            .collect();
        let placement = legend.place(&densify(&data, 4), frame.area(0));
        let right = Frame::legend_room(&legend, placement);
        let mut chart = frame
            .builder(&root, "Neuron training error per pass", right)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(
            &mut chart,
            &xa,
            &ya,
            "training pass",
            "sum of squared residuals (V²)",
        )?;
        chart.draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?;
        if let Some(sse) = sse {
            chart.draw_series(DashedLineSeries::new(
                [(xa.lo, sse), (xa.hi, sse)],
                8,
                6,
                b.stroke_width(2),
            ))?;
        }
        if let Some(t) = online {
            let x = t.online_passes as f64 + 0.5;
            chart.draw_series(LineSeries::new([(x, ya.lo), (x, ya.hi)], g.stroke_width(1)))?;
        }
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

/// Colours of the contour levels, from the minimum (light) to the highest level (dark).
const LEVEL_COLORS: [RGBColor; 10] = [
    RGBColor(253, 231, 37),
    RGBColor(181, 222, 43),
    RGBColor(110, 206, 88),
    RGBColor(53, 183, 121),
    RGBColor(31, 158, 137),
    RGBColor(38, 130, 142),
    RGBColor(49, 104, 142),
    RGBColor(62, 73, 137),
    RGBColor(72, 40, 120),
    RGBColor(68, 1, 84),
];

/// The SSE at the lower edge of each filled level: `min + (max − min)·(k/n)²`, so the level
/// boundaries (the SSE is quadratic in the coefficients) are evenly spaced rings.
pub(crate) fn contour_levels(sse_min: f64, sse_max: f64) -> Vec<f64> {
    let n = LEVEL_COLORS.len();
    (0..n)
        .map(|k| sse_min + (sse_max - sse_min) * (k as f64 / n as f64).powi(2))
        .collect()
}

fn level_of(levels: &[f64], v: f64) -> usize {
    levels.iter().rposition(|l| v >= *l).unwrap_or(0)
}

/// The error surface as a filled contour map with the least-squares optimum and the neuron's
/// result marked.
pub(crate) fn surface_plot(
    surf: &ErrorSurface,
    ls: (f64, f64),
    neuron: Option<(f64, f64)>,
) -> Result<String, ReportError> {
    draw("surface.svg", |s| {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let (plot_area, legend_area) = root.split_horizontally(WIDTH - 170);
        let (sse_min, sse_max) = surf
            .sse
            .iter()
            .flatten()
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(*v), hi.max(*v))
            });
        let levels = if sse_min.is_finite() && sse_max > sse_min {
            contour_levels(sse_min, sse_max)
        } else {
            vec![sse_min.min(0.0)]
        };
        let half = |axis: &[f64]| -> f64 {
            if axis.len() >= 2 {
                (axis[axis.len() - 1] - axis[0]) / (axis.len() - 1) as f64 / 2.0
            } else {
                1e-6
            }
        };
        let (hw, ht) = (half(&surf.weights), half(&surf.thresholds));
        let (x0, x1) = (
            surf.weights.first().copied().unwrap_or(ls.0 - 1e-3) - hw,
            surf.weights.last().copied().unwrap_or(ls.0 + 1e-3) + hw,
        );
        let (y0, y1) = (
            surf.thresholds.first().copied().unwrap_or(ls.1 - 1e-3) - ht,
            surf.thresholds.last().copied().unwrap_or(ls.1 + 1e-3) + ht,
        );
        let mut chart = ChartBuilder::on(&plot_area)
            .caption(
                "Error surface: SSE over (scale factor, bias)",
                (FONT, TITLE_SIZE),
            )
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        // Filled levels: one rectangle per run of equal-level cells along a row.
        let mut rects = Vec::new();
        for (i, row) in surf.sse.iter().enumerate() {
            let Some(&t) = surf.thresholds.get(i) else {
                continue;
            };
            let mut j = 0;
            while j < row.len().min(surf.weights.len()) {
                let lvl = level_of(&levels, row[j]);
                let start = j;
                while j + 1 < row.len().min(surf.weights.len())
                    && level_of(&levels, row[j + 1]) == lvl
                {
                    j += 1;
                }
                let c = LEVEL_COLORS[lvl.min(LEVEL_COLORS.len() - 1)];
                rects.push(Rectangle::new(
                    [
                        (surf.weights[start] - hw, t - ht),
                        (surf.weights[j] + hw, t + ht),
                    ],
                    c.filled(),
                ));
                j += 1;
            }
        }
        chart.draw_series(rects)?;
        chart
            .configure_mesh()
            .x_desc("scale factor K (V/(°/s))")
            .y_desc("bias K0 (V)")
            .x_label_formatter(&|v| format!("{v:.4}"))
            .y_label_formatter(&|v| format!("{v:.3}"))
            .x_labels(6)
            .axis_desc_style((FONT, DESC_SIZE))
            .label_style((FONT, LABEL_SIZE))
            .disable_mesh()
            .draw()?;
        chart.draw_series([Cross::new(ls, 9, BLACK.stroke_width(3))])?;
        if let Some(n) = neuron {
            chart.draw_series([Circle::new(n, 9, RED.stroke_width(2))])?;
        }
        // Legend: the levels, then the markers.
        let l = &legend_area;
        let text =
            |s: &str, x: i32, y: i32| l.draw(&Text::new(s.to_string(), (x, y), (FONT, LABEL_SIZE)));
        text("SSE (V²), from", 10, 22)?;
        for (k, lvl) in levels.iter().enumerate() {
            let y = 44 + 24 * k as i32;
            let c = LEVEL_COLORS[k.min(LEVEL_COLORS.len() - 1)];
            l.draw(&Rectangle::new([(10, y), (34, y + 18)], c.filled()))?;
            l.draw(&Rectangle::new(
                [(10, y), (34, y + 18)],
                BLACK.stroke_width(1),
            ))?;
            text(&gyrocal_fit::display::significant(*lvl, 4), 42, y + 2)?;
        }
        let y = 44 + 24 * levels.len() as i32 + 16;
        l.draw(&Cross::new((22, y + 8), 7, BLACK.stroke_width(3)))?;
        text("least squares", 42, y + 1)?;
        if neuron.is_some() {
            l.draw(&Circle::new((22, y + 34), 7, RED.stroke_width(2)))?;
            text("neuron", 42, y + 27)?;
        }
        root.present()?;
        Ok(())
    })
}

/// Per-step noise (standard deviation of the readings) vs rate.
pub(crate) fn noise_plot(steps: &[StepStats]) -> Result<String, ReportError> {
    draw("noise.svg", |s| {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let raw: Vec<(f64, f64)> = steps
            .iter()
            .filter_map(|st| st.volts_std.map(|v| (st.rate_dps, v)))
            .collect();
        let (f, unit) = volt_unit(max_abs(raw.iter().map(|p| p.1)));
        let pts: Vec<(f64, f64)> = raw.iter().map(|&(w, v)| (w, v * f)).collect();
        let (x0, x1) = padded(pts.iter().map(|p| p.0));
        let (_, y1) = padded(pts.iter().map(|p| p.1).chain([0.0]));
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(0.0, y1, 6));
        let frame = Frame::new(64);
        let mut chart = frame
            .builder(&root, "Noise of the readings per step", 0)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(
            &mut chart,
            &xa,
            &ya,
            "input rate ω (°/s)",
            &format!("std of the readings ({})", ya.scaled_unit(unit)),
        )?;
        let c = RGBColor(31, 119, 180);
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))?;
        root.present()?;
        Ok(())
    })
}

/// The table's measured rate error (measured − demanded) vs rate, ± its standard deviation.
pub(crate) fn rate_error_plot(steps: &[StepStats]) -> Result<String, ReportError> {
    draw("rate-error.svg", |s| {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let raw: Vec<(f64, f64, f64)> = steps
            .iter()
            .filter_map(|st| {
                st.rate_meas_dps.map(|m| {
                    (
                        st.rate_dps,
                        m - st.rate_dps,
                        st.rate_meas_std_dps.unwrap_or(0.0),
                    )
                })
            })
            .collect();
        let (f, unit) = rate_unit(max_abs(raw.iter().map(|p| p.1.abs() + p.2)));
        let (x0, x1) = padded(raw.iter().map(|p| p.0));
        let (y0, y1) = padded(
            raw.iter()
                .flat_map(|p| [(p.1 - p.2) * f, (p.1 + p.2) * f])
                .chain([0.0]),
        );
        let (xa, ya) = (LinearAxis::new(x0, x1, 8), LinearAxis::new(y0, y1, 6));
        let frame = Frame::new(64);
        let mut chart = frame
            .builder(&root, "Rate table: measured − demanded rate", 0)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        mesh(
            &mut chart,
            &xa,
            &ya,
            "demanded rate ω (°/s)",
            &format!("rate error ({})", ya.scaled_unit(unit)),
        )?;
        chart.draw_series(LineSeries::new(
            [(xa.lo, 0.0), (xa.hi, 0.0)],
            BLACK.mix(0.6),
        ))?;
        let c = RGBColor(44, 160, 44);
        chart.draw_series(raw.iter().map(|&(w, e, sd)| {
            ErrorBar::new_vertical(w, (e - sd) * f, e * f, (e + sd) * f, c.stroke_width(2), 8)
        }))?;
        root.present()?;
        Ok(())
    })
}

/// The scale factor of each run with ± one standard error, and their mean.
pub(crate) fn repeatability_plot(ks: &[(f64, Option<f64>)]) -> Result<String, ReportError> {
    draw("repeatability.svg", |s| {
        let root = SVGBackend::with_string(s, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let q = ks.len();
        let mean = ks.iter().map(|k| k.0).sum::<f64>() / q.max(1) as f64;
        let (y0, y1) = padded(
            ks.iter()
                .flat_map(|&(k, se)| [k - se.unwrap_or(0.0), k + se.unwrap_or(0.0)]),
        );
        // one tick per run, at most 20 labelled
        let every = q.div_ceil(20).max(1);
        let xa = LinearAxis::with_ticks(
            0.5,
            q as f64 + 0.5,
            (1..=q).step_by(every).map(|i| i as f64).collect(),
        );
        let ya = LinearAxis::new(y0, y1, 6);
        let g = RGBColor(120, 120, 120);
        let c = fit_color(Method::LeastSquares, Model::Linear);
        let mut legend = Legend::new();
        legend.add(
            format!("mean K = {mean:.7} V/(°/s)"),
            Swatch::Line {
                color: g,
                width: 1,
                dashed: true,
            },
        );
        legend.add(
            "least-squares K ± one standard error",
            Swatch::Line {
                color: c,
                width: 2,
                dashed: false,
            },
        );
        let bars: Vec<(f64, f64)> = ks
            .iter()
            .enumerate()
            .flat_map(|(i, &(k, se))| {
                let se = se.unwrap_or(0.0);
                let x = (i + 1) as f64;
                [(x, k - se), (x, k), (x, k + se)]
            })
            .collect();
        let frame = Frame::new(84);
        let placement = legend.place(&normalised(&bars, &xa, &ya), frame.area(0));
        let right = Frame::legend_room(&legend, placement);
        let mut chart = frame
            .builder(&root, "Scale factor per run (repeatability)", right)
            .build_cartesian_2d(xa.coord(), ya.coord())?;
        let runs = IntegerLabels;
        mesh(
            &mut chart,
            &runs,
            &ya,
            "run",
            &format!("scale factor K ({})", ya.scaled_unit("V/(°/s)")),
        )?;
        chart.draw_series(DashedLineSeries::new(
            [(0.5, mean), (q as f64 + 0.5, mean)],
            8,
            6,
            g.stroke_width(1),
        ))?;
        chart.draw_series(ks.iter().enumerate().map(|(i, &(k, se))| {
            let se = se.unwrap_or(0.0);
            ErrorBar::new_vertical((i + 1) as f64, k - se, k, k + se, c.stroke_width(2), 12)
        }))?;
        legend.draw(&root, chart.plotting_area().get_pixel_range(), placement)?;
        root.present()?;
        Ok(())
    })
}

/// Labels of a category axis numbered 1, 2, 3...
struct IntegerLabels;

impl Labels for IntegerLabels {
    fn label(&self, v: f64) -> String {
        if (v - v.round()).abs() < 1e-9 {
            format!("{v:.0}")
        } else {
            String::new()
        }
    }
}
