//! The run page's plots: server-rendered SVG, drawn by the certificate's own plot code
//! ([`gyrocal_report::live`]) wherever the report has the plot, so a run looks the same live
//! and in its report.
//!
//! Bounded whatever the run's length (a 24-hour drift record's page costs what a 10-minute
//! one's does):
//!
//! - a sweep (and each sweep of a series): the mean output per step against rate with the
//!   least-squares line once there are [`FIT_MIN_POINTS`] steps at two rates or more, and the
//!   residuals: one point per step (the plan's step count);
//! - a drift record: its segments' mean output against the run clock, at most
//!   [`DRIFT_POINTS_MAX`] points (neighbouring segments averaged), and once the record is
//!   analysed, σ(τ) from its `allan.json` (one point per τ);
//! - a run with a chamber: the temperatures from `temps.csv`, at most
//!   [`gyrocal_report::live::TEMPERATURE_POINTS_MAX`] rows.
//!
//! Each figure carries `data-points` (the points drawn), which the browser tests count.
//! Everything read is untrusted: a file that does not parse gives no figure (a note), never a
//! panic.

use std::path::Path;

use gyrocal_fit::{Dataset, Method, Model, Options};
use gyrocal_run::live::StepSummary;

use crate::pages::esc;

/// The fewest steps the fit line and the residuals are drawn from.
pub const FIT_MIN_POINTS: usize = 3;
/// The most points of a drift record's segment plot.
pub const DRIFT_POINTS_MAX: usize = 400;
/// The largest `allan.json` read (a curve is a few kilobytes; the document's segments list
/// grows with the record's gaps).
const MAX_ALLAN_BYTES: u64 = 16 << 20;

/// A figure around `svg` with its caption and point count.
fn figure(id: &str, points: usize, svg: &str, caption: &str) -> String {
    format!(
        "<figure class=\"plot\" id=\"{id}\" data-points=\"{points}\">{svg}\
         <figcaption>{}</figcaption></figure>",
        esc(caption)
    )
}

/// A note where a plot would be.
fn note(id: &str, text: &str) -> String {
    format!(
        "<p class=\"note\" id=\"{id}\" data-points=\"0\">{}</p>",
        esc(text)
    )
}

/// The least-squares line (and only it) through the steps' means: what the live plot shows.
fn analysis(steps: &[StepSummary]) -> Option<gyrocal_fit::Analysis> {
    let pts: Vec<(f64, f64)> = steps
        .iter()
        .map(|s| (s.rate_dps, s.volts))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    if pts.len() < FIT_MIN_POINTS {
        return None;
    }
    let opts = Options {
        models: vec![Model::Linear],
        methods: vec![Method::LeastSquares],
        surface_size: 0,
        ..Options::default()
    };
    gyrocal_fit::analyze(&Dataset::from_pairs(pts), &opts).ok()
}

/// A sweep's plots: the output against rate with the fitted line, and (`residuals`) its
/// residuals.
pub fn sweep(steps: &[StepSummary], residuals: bool) -> String {
    let n = steps
        .iter()
        .filter(|s| s.rate_dps.is_finite() && s.volts.is_finite())
        .count();
    let Some(a) = analysis(steps) else {
        // too few steps (or one rate only) for a line: the points alone
        return figure(
            "plot-volts",
            n,
            &crate::pages::plot(steps, false),
            &format!(
                "Mean output per step against rate; the fitted line from {FIT_MIN_POINTS} steps \
                 at two rates on."
            ),
        );
    };
    let mut h = String::new();
    match gyrocal_report::live::fit_svg(&a) {
        Ok(svg) => h.push_str(&figure(
            "plot-volts",
            n,
            &svg,
            "Mean output per step against rate, with the least-squares line through the steps \
             recorded so far.",
        )),
        Err(e) => h.push_str(&note("plot-volts", &e.to_string())),
    }
    if !residuals {
        return h;
    }
    match gyrocal_report::live::residuals_svg(&a) {
        Ok(svg) => h.push_str(&figure(
            "plot-residuals",
            n,
            &svg,
            "Residuals (measured − fitted) of each step: a bowl is a second-order term, a step \
             apart from its neighbours a disturbed acquisition.",
        )),
        Err(e) => h.push_str(&note("plot-residuals", &e.to_string())),
    }
    h
}

/// Averages neighbouring `(x, y)` into at most `max` points (each the mean of its group).
pub fn bucket_means(pts: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if pts.len() <= max || max == 0 {
        return pts.to_vec();
    }
    let per = pts.len().div_ceil(max);
    pts.chunks(per)
        .map(|c| {
            let n = c.len() as f64;
            (
                c.iter().map(|p| p.0).sum::<f64>() / n,
                c.iter().map(|p| p.1).sum::<f64>() / n,
            )
        })
        .collect()
}

/// A drift record's plots: the segments' means against the run clock and σ(τ): from
/// `dir/allan.json` once the record is analysed, else the running deviation of its live
/// state (`adev_v`, the streaming accumulator's octave points).
pub fn drift(steps: &[StepSummary], dir: Option<&Path>, adev_v: &[(f64, f64)]) -> String {
    let pts: Vec<(f64, f64)> = steps
        .iter()
        .map(|s| (s.t_end_s, s.volts))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let shown = bucket_means(&pts, DRIFT_POINTS_MAX);
    let caption = if shown.len() < pts.len() {
        format!(
            "Mean output of the record's {} segments against the run clock (neighbouring \
             segments averaged into {} points).",
            pts.len(),
            shown.len()
        )
    } else {
        "Mean output of each segment of the record against the run clock.".to_string()
    };
    let mut h = if shown.is_empty() {
        note(
            "plot-volts",
            "The first segment's mean is drawn here once it is recorded.",
        )
    } else {
        match gyrocal_report::live::segments_svg(&shown) {
            Ok(svg) => figure("plot-volts", shown.len(), &svg, &caption),
            Err(e) => note("plot-volts", &e.to_string()),
        }
    };
    h.push_str(&allan(dir, adev_v));
    h
}

/// σ(τ) from `dir/allan.json`, else the running deviation, else a note saying when it comes.
fn allan(dir: Option<&Path>, adev_v: &[(f64, f64)]) -> String {
    let bytes = dir.and_then(|d| read_capped(&d.join("allan.json"), MAX_ALLAN_BYTES));
    let Some(bytes) = bytes else {
        if adev_v.len() >= 2 {
            return match gyrocal_report::live::running_adev_svg(adev_v) {
                Ok(svg) => figure(
                    "plot-allan",
                    adev_v.len(),
                    &svg,
                    "The running overlapping Allan deviation of the readings so far (τ up to \
                     100 s); the record's full σ(τ), with its intervals and noise terms, \
                     replaces it once the record is complete and analysed.",
                ),
                Err(e) => note("plot-allan", &e.to_string()),
            };
        }
        return note(
            "plot-allan",
            "σ(τ) is drawn here as the record runs (from its second octave of readings), then \
             from allan.json once it is complete and analysed.",
        );
    };
    let doc: gyrocal_analysis::drift::AllanDocument = match serde_json::from_slice(&bytes) {
        Ok(d) => d,
        Err(e) => return note("plot-allan", &format!("allan.json: {e}")),
    };
    let n = doc.curve.points.len();
    match gyrocal_report::live::allan_svg(&doc) {
        Ok(svg) => figure(
            "plot-allan",
            n,
            &svg,
            &format!(
                "Allan deviation σ(τ) of the record ({}), with its confidence intervals.",
                doc.unit
            ),
        ),
        Err(e) => note("plot-allan", &e.to_string()),
    }
}

/// The chamber's temperatures from `dir/temps.csv` (none for a run without a chamber).
pub fn temperatures(dir: &Path) -> String {
    let rows = match gyrocal_files::rundir::temps::read_temps(dir) {
        Ok(rows) => rows,
        Err(e) => return note("plot-temps", &e.to_string()),
    };
    if rows.is_empty() {
        return String::new();
    }
    let all: Vec<gyrocal_report::live::TemperatureRow> = rows
        .iter()
        .map(|r| (r.t_s, Some(r.setpoint_c), Some(r.air_c), r.product_c))
        .collect();
    let shown = all.len().min(gyrocal_report::live::TEMPERATURE_POINTS_MAX);
    match gyrocal_report::live::temperatures_svg(&all) {
        Ok(svg) => figure(
            "plot-temps",
            shown,
            &svg,
            &format!(
                "The chamber's setpoint, its air and the gyro's temperature through the run \
                 ({} readings of the chamber{}).",
                all.len(),
                if shown < all.len() {
                    format!(", {shown} drawn")
                } else {
                    String::new()
                }
            ),
        ),
        Err(e) => note("plot-temps", &e.to_string()),
    }
}

/// Reads a file of at most `max` bytes, not through a symlink.
fn read_capped(path: &Path, max: u64) -> Option<Vec<u8>> {
    let meta = std::fs::symlink_metadata(path).ok()?;
    if !meta.is_file() || meta.len() > max {
        return None;
    }
    std::fs::read(path).ok()
}

/// The plots of a run of `kind` in `dir` with its recorded `steps`, side by side where the
/// window is wide enough. A temperature series: its temperatures first, and the output
/// against rate without residuals (one line through every temperature's steps says nothing
/// of a step; the series' own page has the fits at each temperature).
///
/// `dir` is the run directory when this server has it (a run under one of its roots); a run
/// known only through the catalog's live rows has none, and gets the plots its step
/// summaries alone can draw.
pub fn for_run(
    kind: &str,
    steps: &[StepSummary],
    adev_v: &[(f64, f64)],
    dir: Option<&Path>,
) -> String {
    let temps = || dir.map(temperatures).unwrap_or_default();
    let body = match (kind, dir) {
        ("drift", _) => drift(steps, dir, adev_v) + &temps(),
        ("temperature_series", _) => temps() + &sweep(steps, false),
        _ => sweep(steps, true) + &temps(),
    };
    format!("<div class=\"plots\">{body}</div>")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(i: usize, rate: f64, volts: f64) -> StepSummary {
        StepSummary {
            number: i,
            rate_dps: rate,
            volts,
            volts_std: Some(1e-4),
            n: 50,
            overloads: 0,
            t_end_s: i as f64 * 10.0,
        }
    }

    #[test]
    fn a_sweep_gets_its_line_and_residuals_from_three_steps_on() {
        let tmp = tempfile::tempdir().unwrap();
        let two = [step(1, 0.0, 0.01), step(2, 1.0, 0.37)];
        let h = for_run("scale_factor", &two, &[], Some(tmp.path()));
        assert!(h.contains("data-points=\"2\""), "{h}");
        assert!(!h.contains("plot-residuals"), "no residuals from two steps");
        let three = [step(1, 0.0, 0.01), step(2, 1.0, 0.37), step(3, -1.0, -0.35)];
        let h = for_run("scale_factor", &three, &[], Some(tmp.path()));
        assert!(h.contains("id=\"plot-residuals\" data-points=\"3\""), "{h}");
        assert!(
            h.contains("least squares: K = 0.36"),
            "the line's K in the legend"
        );
    }

    #[test]
    fn a_long_drift_record_is_drawn_from_a_bounded_number_of_points() {
        let tmp = tempfile::tempdir().unwrap();
        let steps: Vec<StepSummary> = (1..=5000).map(|i| step(i, 0.0, 0.0088)).collect();
        let h = for_run("drift", &steps, &[], Some(tmp.path()));
        assert!(
            h.contains("data-points=\"385\""),
            "5000 segments in groups of 13"
        );
        assert!(h.matches("<circle").count() <= DRIFT_POINTS_MAX);
        assert!(h.contains("as the record runs"), "no allan.json yet");
    }

    #[test]
    fn a_broken_allan_json_is_a_note_not_a_panic() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("allan.json"), "{\"curve\": 7}").unwrap();
        let h = for_run("drift", &[step(1, 0.0, 0.0)], &[], Some(tmp.path()));
        assert!(h.contains("allan.json: "), "{h}");
    }

    #[test]
    fn a_running_drift_record_draws_its_running_allan_deviation_until_allan_json_comes() {
        let tmp = tempfile::tempdir().unwrap();
        let steps: Vec<StepSummary> = (1..=10).map(|i| step(i, 0.0, 0.0088)).collect();
        // white noise of 30 µV at τ0 = 21.7 ms: σ falls as τ^-1/2 over the octaves
        let adev: Vec<(f64, f64)> = (0..12)
            .map(|k| {
                let tau = 0.0217 * f64::from(1u32 << k);
                (tau, 30e-6 * (0.0217 / tau).sqrt())
            })
            .collect();
        let h = for_run("drift", &steps, &adev, Some(tmp.path()));
        assert!(h.contains("Running Allan deviation"), "{h}");
        assert!(h.contains("id=\"plot-allan\""), "{h}");
        assert!(
            h.contains("data-points=\"12\""),
            "one point per octave: {h}"
        );
        // one point is not a curve yet
        let h = for_run("drift", &steps, &adev[..1], Some(tmp.path()));
        assert!(!h.contains("Running Allan deviation"));
        assert!(h.contains("as the record runs"), "{h}");
        // a run known only through the catalog (no run directory) draws it too
        let h = for_run("drift", &steps, &adev, None);
        assert!(h.contains("Running Allan deviation"), "{h}");
    }
}
