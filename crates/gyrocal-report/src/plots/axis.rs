//! The axis policy of every plot, written once: which ticks an axis gets and how they are
//! labelled.
//!
//! Why a policy of our own rather than plotters' defaults: plotters' logarithmic axis labels
//! whatever key points it finds (on a short range `1.0e1` twice, on a long one none between
//! two decades) and draws a light grid line at every one of its many light points, which on a
//! few decades piles up into a grey bar. A published Allan plot (allantools with matplotlib,
//! IEEE 952's figures) labels every decade and shows minor ticks at 2..9 × each decade; its
//! labels share one format. So:
//!
//! - **log axes** ([`LogAxis`]) run from decade to decade (the range is widened to whole
//!   powers of ten, so every part of the curve, its minimum too, lies between two labelled
//!   ticks); every decade is labelled; the minor ticks are 2..9 × each decade when a decade is
//!   tall enough to show them apart ([`MINOR_ALL_PX`]), 2 and 5 when it is a little smaller,
//!   none below that (no grey bar); an axis of a single decade also labels 2 and 5.
//! - **one label format per axis**: plain decimals (`0.01`, `0.1`, `1`, `10`, `1000`) when
//!   every label lies in 10⁻⁴..10⁵, otherwise powers of ten (`10⁻⁶`, `2×10⁻⁶`) for all.
//! - **linear axes** ([`LinearAxis`]) get ticks at 1, 2 or 5 × 10ⁿ steps, every label with the
//!   same number of decimals (`0.3650`, `0.3655`, never `3.6500e-1`), and no `-0` label; when
//!   the numbers would need more than [`MAX_PLAIN_DECIMALS`] decimals or are ≥ 10⁶, the labels
//!   are scaled by a power of ten that the axis title states (`10⁻⁹ V/(°/s)²`).
//!
//! The plots build their coordinates with `with_key_points(axis.ticks())` and
//! `.with_light_points(axis.minor())`, and label with [`LogAxis::label`] /
//! [`LinearAxis::label`].

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};

/// A coordinate with the ticks of an axis of this module: plotters draws its mesh and labels
/// at exactly these (bold: labelled, light: minor grid lines). Built by [`LinearAxis::coord`]
/// and [`LogAxis::coord`].
#[derive(Debug, Clone)]
pub(crate) struct Ticked {
    lo: f64,
    hi: f64,
    log: bool,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Ranged for Ticked {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, v: &f64, limit: (i32, i32)) -> i32 {
        let t = if self.log {
            (v.ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        };
        let t = if t.is_finite() { t } else { 0.0 };
        let px = f64::from(limit.0) + f64::from(limit.1 - limit.0) * t;
        // far outside the frame is clipped anyway; keep the cast in range
        px.round().clamp(-1e6, 1e6) as i32
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

/// A decade at least this tall (px) shows minor ticks at every 2..9 ×.
pub(crate) const MINOR_ALL_PX: f64 = 90.0;
/// A decade at least this tall (px), but less than [`MINOR_ALL_PX`], shows minor ticks at 2
/// and 5 × only.
pub(crate) const MINOR_SOME_PX: f64 = 30.0;
/// Linear labels with more decimals than this are scaled by a power of ten instead.
pub(crate) const MAX_PLAIN_DECIMALS: i32 = 6;

/// How the labels of a log axis are written (one format for the whole axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum DecadeFormat {
    /// `0.01`, `0.1`, `1`, `10`, `100`.
    Plain,
    /// `10⁻⁶`, `2×10⁻⁶`.
    Power,
}

/// A logarithmic axis from decade to decade.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LogAxis {
    /// Lower end (a power of ten).
    pub lo: f64,
    /// Upper end (a power of ten).
    pub hi: f64,
    /// The labelled ticks, ascending: every decade (and 2, 5 × on a one-decade axis).
    labelled: Vec<f64>,
    /// The minor ticks (unlabelled), ascending.
    minor: Vec<f64>,
    format: DecadeFormat,
}

fn pow10(e: i32) -> f64 {
    10f64.powi(e)
}

/// `v` rounded to its own significant digits so that `2 * 1e-5` prints as `2e-5`, not
/// `2.0000000000000002e-5`.
fn clean(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let e = v.abs().log10().floor() as i32;
    let m = (v / pow10(e) * 1e9).round() / 1e9;
    m * pow10(e)
}

impl LogAxis {
    /// The axis for data between `lo` and `hi` (positive; anything else gives 0.1..10), drawn
    /// `pixels` long: widened to the enclosing decades.
    pub(crate) fn new(lo: f64, hi: f64, pixels: f64) -> LogAxis {
        let (lo, hi) = if lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo {
            (lo, hi)
        } else {
            (0.1, 10.0)
        };
        // a hair of tolerance: 1000 computed as 999.9999999 still starts its own decade
        let e0 = (lo.log10() + 1e-9).floor() as i32;
        let mut e1 = (hi.log10() - 1e-9).ceil() as i32;
        if e1 <= e0 {
            e1 = e0 + 1;
        }
        let decades = e1 - e0;
        let px = pixels / f64::from(decades.max(1));
        let mut labelled: Vec<f64> = (e0..=e1).map(pow10).collect();
        let minor_mults: &[f64] = if px >= MINOR_ALL_PX {
            &[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
        } else if px >= MINOR_SOME_PX {
            &[2.0, 5.0]
        } else {
            &[]
        };
        let mut minor: Vec<f64> = (e0..e1)
            .flat_map(|e| minor_mults.iter().map(move |m| clean(m * pow10(e))))
            .collect();
        if decades == 1 {
            labelled = vec![
                pow10(e0),
                clean(2.0 * pow10(e0)),
                clean(5.0 * pow10(e0)),
                pow10(e1),
            ];
            minor.retain(|m| !labelled.contains(m));
        }
        let format = if labelled.iter().all(|v| (1e-4..=1e5).contains(v)) {
            DecadeFormat::Plain
        } else {
            DecadeFormat::Power
        };
        LogAxis {
            lo: pow10(e0),
            hi: pow10(e1),
            labelled,
            minor,
            format,
        }
    }

    /// The labelled ticks, ascending.
    #[cfg(test)]
    pub(crate) fn ticks(&self) -> Vec<f64> {
        self.labelled.clone()
    }

    /// The minor (unlabelled) ticks, ascending.
    #[cfg(test)]
    pub(crate) fn minor(&self) -> Vec<f64> {
        self.minor.clone()
    }

    /// The coordinate to build a chart on.
    pub(crate) fn coord(&self) -> Ticked {
        Ticked {
            lo: self.lo,
            hi: self.hi,
            log: true,
            bold: self.labelled.clone(),
            light: self.minor.clone(),
        }
    }

    /// The label format of this axis.
    #[cfg(test)]
    pub(crate) fn format(&self) -> DecadeFormat {
        self.format
    }

    /// The label of a tick of this axis (empty for a value that is not one of its ticks).
    pub(crate) fn label(&self, v: f64) -> String {
        if !self
            .labelled
            .iter()
            .any(|t| (t - v).abs() <= t.abs() * 1e-9)
        {
            return String::new();
        }
        match self.format {
            DecadeFormat::Plain => plain_decade(v),
            DecadeFormat::Power => power_decade(v),
        }
    }
}

/// `0.001`, `0.5`, `1`, `20`, `1000`: as many decimals as the value needs, no more.
fn plain_decade(v: f64) -> String {
    let e = v.abs().log10().floor() as i32;
    let decimals = usize::try_from(-e).unwrap_or(0);
    format!("{v:.decimals$}")
}

const SUPERSCRIPT: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];

/// `10⁻⁶`, `10¹²`.
pub(crate) fn power_of_ten(e: i32) -> String {
    let mut s = String::from("10");
    if e < 0 {
        s.push('⁻');
    }
    for d in e.unsigned_abs().to_string().bytes() {
        s.push(SUPERSCRIPT[usize::from(d - b'0')]);
    }
    s
}

/// `10⁻⁶`, `2×10⁻⁶`.
fn power_decade(v: f64) -> String {
    let e = v.abs().log10().floor() as i32;
    let m = (v / pow10(e)).round();
    if m == 1.0 {
        power_of_ten(e)
    } else {
        format!("{m:.0}×{}", power_of_ten(e))
    }
}

/// A linear axis with ticks at a 1, 2 or 5 × 10ⁿ step and one label format.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LinearAxis {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
    ticks: Vec<f64>,
    /// Decimals of every label (after scaling).
    decimals: usize,
    /// The labels are `value / 10^scale` (0: not scaled).
    scale: i32,
}

impl LinearAxis {
    /// The axis over `lo..hi` (the range as given: pad it before) with about `target` ticks
    /// (at least 2).
    pub(crate) fn new(lo: f64, hi: f64, target: usize) -> LinearAxis {
        let (lo, hi) = if lo.is_finite() && hi.is_finite() && hi > lo {
            (lo, hi)
        } else if lo.is_finite() {
            let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
            (lo - d, lo + d)
        } else {
            (-1.0, 1.0)
        };
        let raw = (hi - lo) / target.max(2) as f64;
        let e = raw.log10().floor() as i32;
        let base = pow10(e);
        let m = raw / base;
        let (mult, e) = if m <= 1.0 {
            (1.0, e)
        } else if m <= 2.0 {
            (2.0, e)
        } else if m <= 5.0 {
            (5.0, e)
        } else {
            (1.0, e + 1)
        };
        let step = mult * pow10(e);
        let first = (lo / step).ceil() as i64;
        let last = (hi / step).floor() as i64;
        let ticks: Vec<f64> = (first..=last.max(first))
            .map(|i| i as f64 * step)
            .filter(|v| *v >= lo - step * 1e-9 && *v <= hi + step * 1e-9)
            .map(|v| if v.abs() < step * 1e-6 { 0.0 } else { v })
            .collect();
        let magnitude = ticks.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(step);
        let decimals = (-e).max(0);
        let top = magnitude.log10().floor() as i32;
        let scale = if decimals > MAX_PLAIN_DECIMALS || top >= 6 {
            // scale by the largest multiple of 3 not above the magnitude: engineering style
            top.div_euclid(3) * 3
        } else {
            0
        };
        let decimals = usize::try_from((scale - e).max(0)).unwrap_or(0);
        LinearAxis {
            lo,
            hi,
            ticks,
            decimals,
            scale,
        }
    }

    /// The labelled ticks, ascending.
    #[cfg(test)]
    pub(crate) fn ticks(&self) -> Vec<f64> {
        self.ticks.clone()
    }

    /// An axis over `lo..hi` with ticks of the caller's (a category axis: one per
    /// calibration), labelled by the caller.
    pub(crate) fn with_ticks(lo: f64, hi: f64, ticks: Vec<f64>) -> LinearAxis {
        LinearAxis {
            lo,
            hi,
            ticks,
            decimals: 0,
            scale: 0,
        }
    }

    /// The coordinate to build a chart on.
    pub(crate) fn coord(&self) -> Ticked {
        Ticked {
            lo: self.lo,
            hi: self.hi,
            log: false,
            bold: self.ticks.clone(),
            light: Vec::new(),
        }
    }

    /// The label of a value on this axis: `value / 10^scale` with the axis's decimals; never
    /// `-0`.
    pub(crate) fn label(&self, v: f64) -> String {
        let x = v / pow10(self.scale);
        let d = self.decimals;
        let s = format!("{x:.d$}");
        if s.trim_start_matches('-')
            .chars()
            .all(|c| c == '0' || c == '.')
        {
            return format!("{:.d$}", 0.0);
        }
        s.replace('-', "−")
    }

    /// The unit for the axis title: `unit` itself, or `10⁻⁹ unit` when the labels are scaled
    /// (a label 1.2 then reads 1.2 × 10⁻⁹ unit).
    pub(crate) fn scaled_unit(&self, unit: &str) -> String {
        if self.scale == 0 {
            unit.to_string()
        } else {
            format!("{} {unit}", power_of_ten(self.scale))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(a: &LogAxis) -> Vec<String> {
        a.ticks().iter().map(|t| a.label(*t)).collect()
    }

    #[test]
    fn every_decade_is_labelled_in_one_format() {
        let a = LogAxis::new(0.5, 2000.0, 400.0);
        assert_eq!(a.ticks(), vec![0.1, 1.0, 10.0, 100.0, 1000.0, 10000.0]);
        assert_eq!(labels(&a), ["0.1", "1", "10", "100", "1000", "10000"]);
        assert_eq!((a.lo, a.hi), (0.1, 10000.0));
        assert_eq!(a.format(), DecadeFormat::Plain);
    }

    #[test]
    fn data_on_decades_keeps_its_decades() {
        let a = LogAxis::new(1.0, 1000.0, 400.0);
        assert_eq!(a.ticks(), vec![1.0, 10.0, 100.0, 1000.0]);
    }

    #[test]
    fn small_values_are_powers_of_ten_all_of_them() {
        let a = LogAxis::new(3e-7, 2e-3, 400.0);
        assert_eq!(
            labels(&a),
            ["10⁻⁷", "10⁻⁶", "10⁻⁵", "10⁻⁴", "10⁻³", "10⁻²"],
            "one format: no 1e-1 beside 1.0e0"
        );
        assert_eq!(a.format(), DecadeFormat::Power);
    }

    #[test]
    fn no_label_is_drawn_twice() {
        for (lo, hi) in [(2.0, 30.0), (0.72, 14.0), (9.0, 11.0), (1e-9, 1e9)] {
            let a = LogAxis::new(lo, hi, 450.0);
            let l = labels(&a);
            let mut d = l.clone();
            d.dedup();
            assert_eq!(l, d, "{lo}..{hi}");
            assert!(l.iter().all(|s| !s.is_empty()));
        }
    }

    #[test]
    fn the_minimum_of_the_curve_lies_between_two_labels() {
        // the Allan curve: minimum 0.72 °/h, top 14
        let a = LogAxis::new(0.72 / 2.0, 14.0 * 2.0, 450.0);
        let below = a.ticks().into_iter().filter(|t| *t <= 0.72).count();
        let above = a.ticks().into_iter().filter(|t| *t >= 0.72).count();
        assert!(below >= 1 && above >= 1, "{:?}", a.ticks());
        assert_eq!(labels(&a), ["0.1", "1", "10", "100"]);
    }

    #[test]
    fn minor_ticks_only_where_they_do_not_make_a_grey_bar() {
        // 3 decades in 450 px: 150 px a decade, every 2..9
        let a = LogAxis::new(0.01, 10.0, 450.0);
        assert_eq!(a.minor().len(), 3 * 8);
        // 9 decades in 450 px: 50 px a decade, 2 and 5 only
        let a = LogAxis::new(1e-6, 1e3, 450.0);
        assert_eq!(a.minor().len(), 9 * 2);
        // 20 decades: none
        assert!(LogAxis::new(1e-10, 1e10, 450.0).minor().is_empty());
        // no two minor lines closer than 4 px anywhere
        for (lo, hi) in [(0.01, 10.0), (1e-6, 1e3), (0.5, 2000.0)] {
            let a = LogAxis::new(lo, hi, 450.0);
            let px = |v: f64| (v.log10() - a.lo.log10()) / (a.hi.log10() - a.lo.log10()) * 450.0;
            let mut all: Vec<f64> = a.minor().into_iter().chain(a.ticks()).map(px).collect();
            all.sort_by(f64::total_cmp);
            assert!(all.windows(2).all(|w| w[1] - w[0] >= 4.0), "{lo}..{hi}");
        }
    }

    #[test]
    fn a_one_decade_axis_labels_two_and_five_too() {
        let a = LogAxis::new(0.2, 0.9, 450.0);
        assert_eq!(labels(&a), ["0.1", "0.2", "0.5", "1"]);
        assert!(!a.minor().contains(&0.2));
    }

    #[test]
    fn linear_labels_share_their_decimals_and_never_say_minus_zero() {
        let a = LinearAxis::new(0.36488, 0.36512, 5);
        let l: Vec<String> = a.ticks().iter().map(|t| a.label(*t)).collect();
        assert_eq!(l, ["0.36490", "0.36495", "0.36500", "0.36505", "0.36510"]);
        assert!(l.iter().all(|s| !s.contains('e')));
        let a = LinearAxis::new(-0.25, 0.25, 5);
        let l: Vec<String> = a.ticks().iter().map(|t| a.label(*t)).collect();
        assert_eq!(l, ["−0.2", "−0.1", "0.0", "0.1", "0.2"]);
        assert_eq!(a.label(-1e-17), "0.0");
    }

    #[test]
    fn tiny_or_huge_numbers_are_scaled_and_the_title_says_by_what() {
        let a = LinearAxis::new(1.0e-9, 1.5e-9, 5);
        assert_eq!(a.scaled_unit("V/(°/s)²"), "10⁻⁹ V/(°/s)²");
        let l: Vec<String> = a.ticks().iter().map(|t| a.label(*t)).collect();
        assert_eq!(l, ["1.0", "1.1", "1.2", "1.3", "1.4", "1.5"]);
        let a = LinearAxis::new(2.0e6, 8.0e6, 3);
        assert_eq!(a.scaled_unit("V"), "10⁶ V");
        assert_eq!(LinearAxis::new(0.0, 1.0, 5).scaled_unit("V"), "V");
        assert_eq!(a.label(4.0e6), "4");
    }
}
