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
