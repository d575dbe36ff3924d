//! The Allan analysis of a run directory (samples.csv, fit.json) and its page.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::Path;

use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_analysis::drift::{AllanOptions, WarmupOptions, analyse_input};
use gyrocal_report::allan::render_allan;

const K: f64 = 0.02;
const TAU0: f64 = 0.5;

/// A run directory of a drift run at rest: `n` readings, the ones in `overloads` written as
/// overloads (empty volts), the output starting `warm` °/h high and settling with a 120 s
/// time constant; fit.json with the scale factor K.
fn run_dir(dir: &Path, n: usize, overloads: &[usize], warm: f64) {
    let noise = GyroNoise {
        arw_deg_per_sqrt_h: 0.05,
        bias_instability_deg_per_h: 0.5,
        ..GyroNoise::default()
    };
    let rate = generate(&noise, TAU0, n, 11).unwrap();
    let mut s = String::from("step,index,t_s,rate_dps,volts,overload,t_utc\n");
    for (i, r) in rate.iter().enumerate() {
        let t = i as f64 * TAU0;
        let r = r + warm * (-t / 120.0).exp();
        if overloads.contains(&i) {
            let _ = writeln!(s, "0,{i},{t},0,,1,2026-03-21T10:00:00.000Z");
        } else {
            let v = r / 3600.0 * K;
            let _ = writeln!(s, "0,{i},{t},0,{v:.10e},0,2026-03-21T10:00:00.000Z");
        }
    }
    std::fs::write(dir.join("samples.csv"), s).unwrap();
    std::fs::write(
        dir.join("fit.json"),
        format!("{{\"metrics\": {{\"scale_factor\": {K}}}}}"),
    )
    .unwrap();
}

#[test]
fn a_run_directory_uses_its_scale_factor_and_skips_overloads() {
    let tmp = tempfile::tempdir().unwrap();
    run_dir(tmp.path(), 20_000, &[500], 0.0);
    let doc = analyse_input(tmp.path(), &AllanOptions::default()).unwrap();
    let k = doc.scale_factor.as_ref().unwrap();
    assert_eq!(k.v_per_dps, K);
    assert!(k.source.ends_with("fit.json"));
    assert_eq!(doc.unit, "deg/h");
    assert_eq!(doc.rows, 20_000);
    assert_eq!(doc.overloads_skipped, 1);
    assert_eq!(doc.tau0_s, TAU0);
    // the overload leaves a gap: two segments, the longer (after it) analysed
    assert_eq!(doc.segments.len(), 2);
    assert_eq!(doc.segments[0].samples, 500);
    assert_eq!(doc.segments[1].samples, 19_499);
    assert_eq!(doc.analysed.segment, 1);
    assert!(doc.notes.iter().any(|n| n.contains("overload")));
    assert!(doc.notes.iter().any(|n| n.contains("only the longest")));
    let nt = doc.noise_terms.as_ref().unwrap();
    let arw = &nt.fit.as_ref().unwrap().terms[1].value;
    assert!((arw.value - 0.05).abs() < 0.01, "{arw:?}");

    // the document round-trips through JSON
    let json = serde_json::to_string(&doc).unwrap();
    let back: gyrocal_analysis::drift::AllanDocument = serde_json::from_str(&json).unwrap();
    assert_eq!(back.segments, doc.segments);

    // the page: its SVGs are well-formed XML, the table is there
    let html = render_allan(&doc).unwrap();
    let mut rest = html.as_str();
    let mut svgs = 0;
    while let Some(i) = rest.find("<svg") {
        let j = rest[i..].find("</svg>").unwrap() + i + 6;
        roxmltree::Document::parse(&rest[i..j]).unwrap();
        svgs += 1;
        rest = &rest[j..];
    }
    assert_eq!(svgs, 2);
    assert!(html.contains("id=\"noise-terms\""));
    assert!(html.contains("only the longest"));
}

#[test]
fn the_warm_up_is_found_and_cut() {
    let tmp = tempfile::tempdir().unwrap();
    // 50 °/h at power-on, settling with τ = 120 s
    run_dir(tmp.path(), 14_400, &[], 50.0);
    let doc = analyse_input(tmp.path(), &AllanOptions::default()).unwrap();
    let w = doc.warmup.as_ref().unwrap();
    assert_eq!(w.ended_by, "criterion");
    assert!(w.time_s >= 300.0 && w.time_s <= 1200.0, "{w:?}");
    assert_eq!(
        doc.analysed.warmup_samples,
        (w.time_s / TAU0).round() as usize
    );
    assert_eq!(doc.analysed.samples, 14_400 - doc.analysed.warmup_samples);
    // a cap ends it earlier
    let opts = AllanOptions {
        warmup: WarmupOptions {
            max_s: Some(60.0),
            ..WarmupOptions::default()
        },
        ..AllanOptions::default()
    };
    let doc = analyse_input(tmp.path(), &opts).unwrap();
    let w = doc.warmup.as_ref().unwrap();
    assert_eq!((w.time_s, w.ended_by.as_str()), (60.0, "max"));
}

#[test]
fn write_run_allan_writes_the_json_and_the_page() {
    let tmp = tempfile::tempdir().unwrap();
    run_dir(tmp.path(), 4_000, &[], 0.0);
    let (doc, files) =
        gyrocal_report::write_run_allan(tmp.path(), &AllanOptions::default()).unwrap();
    assert_eq!(files.len(), 2);
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("allan.json")).unwrap()).unwrap();
    assert_eq!(v["analysed"]["samples"], doc.analysed.samples);
    assert!(
        std::fs::read_to_string(tmp.path().join("allan.html"))
            .unwrap()
            .contains("<svg")
    );
}

/// The σ(τ) plot of a page: its tick labels per axis (y: right-aligned left of the frame; x:
/// centred under it), the legend's box and the points' centres.
struct CurvePlot {
    y_labels: Vec<String>,
    x_labels: Vec<String>,
    legend: (f64, f64, f64, f64),
    points: Vec<(f64, f64)>,
}

fn curve_plot(html: &str) -> CurvePlot {
    let start = html.find("<svg").unwrap();
    let end = html[start..].find("</svg>").unwrap() + start + 6;
    let doc = roxmltree::Document::parse(&html[start..end]).unwrap();
    let num = |n: &roxmltree::Node, a: &str| n.attribute(a).unwrap().parse::<f64>().unwrap();
    let mut p = CurvePlot {
        y_labels: Vec::new(),
        x_labels: Vec::new(),
        legend: (0.0, 0.0, 0.0, 0.0),
        points: Vec::new(),
    };
    for n in doc.descendants() {
        if n.has_tag_name("text") && n.attribute("transform").is_none() {
            let t = n.text().unwrap_or("").trim().to_string();
            match (n.attribute("text-anchor"), n.attribute("dy")) {
                (Some("end"), _) => p.y_labels.push(t),
                (Some("middle"), Some("0.76em")) if num(&n, "y") > 400.0 => p.x_labels.push(t),
                _ => {}
            }
        } else if n.has_tag_name("rect") && n.attribute("opacity") == Some("0.92") {
            p.legend = (
                num(&n, "x"),
                num(&n, "y"),
                num(&n, "width"),
                num(&n, "height"),
            );
        } else if n.has_tag_name("circle") && n.attribute("r") == Some("3") {
            // the points (r 3; the legend's own swatch dot is r 4)
            p.points.push((num(&n, "cx"), num(&n, "cy")));
        }
    }
    p
}

/// Issue 25: the Allan plot's axes are labelled at every decade, in one format, no label
/// twice, the curve's minimum between two labels, and the legend covers no point.
#[test]
fn the_allan_plot_labels_every_decade_once_and_its_legend_covers_no_point() {
    let tmp = tempfile::tempdir().unwrap();
    run_dir(tmp.path(), 20_000, &[], 0.0);
    let doc = analyse_input(tmp.path(), &AllanOptions::default()).unwrap();
    let html = render_allan(&doc).unwrap();
    let p = curve_plot(&html);
    for labels in [&p.y_labels, &p.x_labels] {
        assert!(labels.len() >= 2, "{labels:?}");
        let values: Vec<f64> = labels
            .iter()
            .map(|l| {
                l.parse::<f64>()
                    .unwrap_or_else(|_| panic!("{l:?} in {labels:?}"))
            })
            .collect();
        // consecutive decades (1 ... 10 ... 100): every decade labelled, none twice
        for w in values.windows(2) {
            let r = (w[0] / w[1]).max(w[1] / w[0]);
            assert!((r - 10.0).abs() < 1e-9, "{labels:?}");
        }
        // one format: plain decimals, no exponent form anywhere
        assert!(labels.iter().all(|l| !l.contains('e')), "{labels:?}");
    }
    let ys: Vec<f64> = p.y_labels.iter().map(|l| l.parse().unwrap()).collect();
    let (lo, hi) = (
        ys.iter().copied().fold(f64::INFINITY, f64::min),
        ys.iter().copied().fold(0.0, f64::max),
    );
    let min = doc
        .curve
        .points
        .iter()
        .map(|q| q.deviation)
        .fold(f64::INFINITY, f64::min);
    assert!(lo < min && min < hi, "{min} within {ys:?}");
    let (x, y, w, h) = p.legend;
    assert!(w > 0.0 && h > 0.0, "a legend");
    assert!(p.points.len() > 10);
    for (cx, cy) in &p.points {
        assert!(
            !(*cx >= x - 3.0 && *cx <= x + w + 3.0 && *cy >= y - 3.0 && *cy <= y + h + 3.0),
            "point ({cx}, {cy}) under the legend {:?}",
            p.legend
        );
    }
}
