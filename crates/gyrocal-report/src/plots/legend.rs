//! Legends that cover no data: drawn by us (not plotters' series labels, which sit at a fixed
//! position whatever lies beneath) at the emptiest corner of the plot, or beside the plot when
//! every corner holds data.
//!
//! The placement is decided before the chart is built, in the plot's own normalised
//! coordinates (0..1 across and up the plotting area): [`place`] takes the data's positions
//! (points, error-bar ends, the curve that matters) and the legend's size, and returns the
//! first free corner in the order upper right, upper left, lower right, lower left, or
//! [`Placement::Outside`], for which the plot reserves a column to its right
//! ([`Legend::width`]).

use plotters::coord::Shift;
use plotters::prelude::*;

const FONT: &str = "sans-serif";
/// Legend text size, px.
pub(crate) const LEGEND_FONT: u32 = 13;
/// Height of one entry, px.
const ROW: i32 = 19;
/// Inner padding, px.
const PAD: i32 = 8;
/// Width of a swatch, px.
const SWATCH: i32 = 26;
/// Average width of a character of the legend font, px (sans-serif at 13 px averages about
/// 6.2; a little more so that the box never clips its text).
const CHAR_PX: f64 = 6.4;
/// Gap kept between the legend and the frame, px.
const INSET: i32 = 6;

/// How an entry is shown.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Swatch {
    /// A line, solid or dashed.
    Line {
        color: RGBColor,
        width: u32,
        dashed: bool,
    },
    /// A filled circle.
    Dot(RGBColor),
    /// A filled triangle (the out-of-limit marker).
    Triangle(RGBColor),
    /// A filled diamond (the marginal marker).
    Diamond(RGBColor),
    /// A filled band.
    Band(RGBAColor),
}

/// Where the legend goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Placement {
    /// Inside the plotting area, at this corner.
    Corner(Corner),
    /// In a column to the right of the plotting area.
    Outside,
}

/// A corner of the plotting area.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Corner {
    UpperRight,
    UpperLeft,
    LowerRight,
    LowerLeft,
}

/// A legend: its entries, in order.
#[derive(Debug, Clone, Default)]
pub(crate) struct Legend {
    entries: Vec<(String, Swatch)>,
}

impl Legend {
    pub(crate) fn new() -> Legend {
        Legend::default()
    }

    /// Adds an entry.
    pub(crate) fn add(&mut self, label: impl Into<String>, swatch: Swatch) {
        self.entries.push((label.into(), swatch));
    }

    /// Whether it has no entry.
    pub(crate) fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Width of the box, px.
    pub(crate) fn width(&self) -> i32 {
        let chars = self
            .entries
            .iter()
            .map(|(l, _)| l.chars().count())
            .max()
            .unwrap_or(0);
        PAD * 3 + SWATCH + (chars as f64 * CHAR_PX).ceil() as i32
    }

    /// Height of the box, px.
    pub(crate) fn height(&self) -> i32 {
        PAD * 2 + ROW * self.entries.len() as i32
    }

    /// Where the legend goes in a plotting area of `area_px` (width, height) holding data at
    /// `points` (normalised: 0..1 from left to right and from bottom to top).
    pub(crate) fn place(&self, points: &[(f64, f64)], area_px: (f64, f64)) -> Placement {
        place(
            points,
            (
                f64::from(self.width() + INSET),
                f64::from(self.height() + INSET),
            ),
            area_px,
        )
    }

    /// Draws the legend at `placement` on `root`, beside or inside the chart whose plotting
    /// area spans `plot` (pixel ranges of x and y, as `plotting_area().get_pixel_range()`).
    pub(crate) fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        plot: (std::ops::Range<i32>, std::ops::Range<i32>),
        placement: Placement,
    ) -> Result<(), Box<dyn std::error::Error>>
    where
        DB::ErrorType: 'static,
    {
        if self.is_empty() {
            return Ok(());
        }
        let (w, h) = (self.width(), self.height());
        let (xs, ys) = plot;
        let (x, y) = match placement {
            Placement::Corner(Corner::UpperRight) => (xs.end - w - INSET, ys.start + INSET),
            Placement::Corner(Corner::UpperLeft) => (xs.start + INSET, ys.start + INSET),
            Placement::Corner(Corner::LowerRight) => (xs.end - w - INSET, ys.end - h - INSET),
            Placement::Corner(Corner::LowerLeft) => (xs.start + INSET, ys.end - h - INSET),
            // against the frame's right edge: the room the plot reserved for it (beyond a
            // right-hand axis too)
            Placement::Outside => {
                let right = i32::try_from(root.dim_in_pixel().0).unwrap_or(xs.end + w);
                (right - w - 2 * INSET, ys.start)
            }
        };
        root.draw(&Rectangle::new(
            [(x, y), (x + w, y + h)],
            WHITE.mix(0.92).filled(),
        ))?;
        root.draw(&Rectangle::new(
            [(x, y), (x + w, y + h)],
            RGBColor(205, 205, 205).stroke_width(1),
        ))?;
        for (i, (label, swatch)) in self.entries.iter().enumerate() {
            let cy = y + PAD + ROW * i as i32 + ROW / 2;
            let sx = x + PAD;
            match *swatch {
                Swatch::Line {
                    color,
                    width,
                    dashed,
                } => {
                    let style = color.stroke_width(width);
                    if dashed {
                        for k in 0..3 {
                            let a = sx + k * 10;
                            root.draw(&PathElement::new(vec![(a, cy), (a + 6, cy)], style))?;
                        }
                    } else {
                        root.draw(&PathElement::new(vec![(sx, cy), (sx + SWATCH, cy)], style))?;
                    }
                }
                Swatch::Dot(c) => root.draw(&Circle::new((sx + SWATCH / 2, cy), 4, c.filled()))?,
                Swatch::Triangle(c) => {
                    root.draw(&TriangleMarker::new((sx + SWATCH / 2, cy), 6, c.filled()))?
                }
                Swatch::Diamond(c) => root.draw(&diamond((sx + SWATCH / 2, cy), 5, c))?,
                Swatch::Band(c) => root.draw(&Rectangle::new(
                    [(sx, cy - 6), (sx + SWATCH, cy + 6)],
                    c.filled(),
                ))?,
            }
            root.draw(&Text::new(
                label.clone(),
                (sx + SWATCH + PAD, cy - LEGEND_FONT as i32 / 2 - 1),
                (FONT, LEGEND_FONT),
            ))?;
        }
        Ok(())
    }
}

/// A filled diamond centred on `c`, `r` px from centre to each tip.
pub(crate) fn diamond<C: Color>(c: (i32, i32), r: i32, color: C) -> Polygon<(i32, i32)> {
    let (x, y) = c;
    Polygon::new(
        vec![(x, y - r), (x + r, y), (x, y + r), (x - r, y)],
        color.filled(),
    )
}

/// The first corner (upper right, upper left, lower right, lower left) where a box of `size`
/// px fits in a plotting area of `area_px` without covering any of `points` (normalised
/// 0..1, y up), each given a margin of a few pixels; [`Placement::Outside`] when none does
/// (or the box is larger than the area).
pub(crate) fn place(points: &[(f64, f64)], size: (f64, f64), area_px: (f64, f64)) -> Placement {
    let (aw, ah) = area_px;
    if aw <= 0.0 || ah <= 0.0 || size.0 >= aw * 0.9 || size.1 >= ah * 0.9 {
        return Placement::Outside;
    }
    // a point's marker reaches about 6 px beyond its centre
    let (mx, my) = (6.0 / aw, 6.0 / ah);
    let (w, h) = (size.0 / aw + mx, size.1 / ah + my);
    let free = |x0: f64, x1: f64, y0: f64, y1: f64| {
        !points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .any(|&(x, y)| x >= x0 && x <= x1 && y >= y0 && y <= y1)
    };
    for corner in [
        Corner::UpperRight,
        Corner::UpperLeft,
        Corner::LowerRight,
        Corner::LowerLeft,
    ] {
        let (x0, x1) = match corner {
            Corner::UpperRight | Corner::LowerRight => (1.0 - w, 1.0),
            Corner::UpperLeft | Corner::LowerLeft => (0.0, w),
        };
        let (y0, y1) = match corner {
            Corner::UpperRight | Corner::UpperLeft => (1.0 - h, 1.0),
            Corner::LowerRight | Corner::LowerLeft => (0.0, h),
        };
        if free(x0, x1, y0, y1) {
            return Placement::Corner(corner);
        }
    }
    Placement::Outside
}

/// `v` in 0..1 across a linear axis `lo..hi`.
pub(crate) fn norm_lin(v: f64, lo: f64, hi: f64) -> f64 {
    (v - lo) / (hi - lo)
}

/// `v` in 0..1 across a logarithmic axis `lo..hi`.
pub(crate) fn norm_log(v: f64, lo: f64, hi: f64) -> f64 {
    (v.ln() - lo.ln()) / (hi.ln() - lo.ln())
}

/// `n` points along the polyline `line` (normalised), so that a curve counts as data where it
/// runs between its vertices too.
pub(crate) fn densify(line: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for w in line.windows(2) {
        let (a, b) = (w[0], w[1]);
        for k in 0..n {
            let t = k as f64 / n as f64;
            out.push((a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t));
        }
    }
    out.extend(line.last());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const AREA: (f64, f64) = (600.0, 350.0);

    fn covered(points: &[(f64, f64)], size: (f64, f64), p: Placement) -> usize {
        let (w, h) = (size.0 / AREA.0, size.1 / AREA.1);
        let Placement::Corner(c) = p else { return 0 };
        let (x0, x1) = match c {
            Corner::UpperRight | Corner::LowerRight => (1.0 - w, 1.0),
            _ => (0.0, w),
        };
        let (y0, y1) = match c {
            Corner::UpperRight | Corner::UpperLeft => (1.0 - h, 1.0),
            _ => (0.0, h),
        };
        points
            .iter()
            .filter(|&&(x, y)| x >= x0 && x <= x1 && y >= y0 && y <= y1)
            .count()
    }

    #[test]
    fn an_empty_upper_right_is_taken() {
        let pts = [(0.1, 0.1), (0.5, 0.5)];
        assert_eq!(
            place(&pts, (150.0, 60.0), AREA),
            Placement::Corner(Corner::UpperRight)
        );
    }

    #[test]
    fn the_legend_moves_off_a_point_in_its_corner() {
        // a point in the upper right corner (the Allan legend covered one)
        let pts = [(0.95, 0.95), (0.5, 0.5)];
        let p = place(&pts, (150.0, 60.0), AREA);
        assert_eq!(p, Placement::Corner(Corner::UpperLeft));
        assert_eq!(covered(&pts, (150.0, 60.0), p), 0);
    }

    #[test]
    fn a_v_shaped_curve_leaves_the_legend_a_lower_corner() {
        // an Allan curve: high at both ends, its minimum in the middle bottom
        let pts: Vec<(f64, f64)> = (0..=40)
            .map(|i| {
                let x = f64::from(i) / 40.0;
                (x, 0.2 + 1.6 * (x - 0.5).powi(2) * 2.0)
            })
            .collect();
        let p = place(&pts, (200.0, 80.0), AREA);
        assert_eq!(p, Placement::Corner(Corner::LowerRight));
        assert_eq!(covered(&pts, (200.0, 80.0), p), 0);
    }

    #[test]
    fn with_every_corner_taken_it_goes_outside() {
        let pts = [(0.02, 0.02), (0.98, 0.02), (0.02, 0.98), (0.98, 0.98)];
        assert_eq!(place(&pts, (150.0, 60.0), AREA), Placement::Outside);
        // and a box too large for the plot goes outside as well
        assert_eq!(place(&[], (590.0, 60.0), AREA), Placement::Outside);
    }

    #[test]
    fn a_curve_counts_between_its_vertices() {
        // two vertices far apart whose segment crosses the upper right corner
        let line = [(0.5, 1.0), (1.0, 0.5)];
        assert_eq!(
            place(&line, (100.0, 40.0), AREA),
            Placement::Corner(Corner::UpperRight),
            "the vertices alone leave the corner free"
        );
        assert_ne!(
            place(&densify(&line, 50), (200.0, 120.0), AREA),
            Placement::Corner(Corner::UpperRight)
        );
    }
}
