//! `gyrocal allan` as a user runs it: noise terms recovered from a simulated record, gaps,
//! bad input with exit code 2, the HTML page.

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Output;

/// `gyrocal ARGS` run to its end, through tests/common.
use common::gyrocal_output as gyrocal;

use gyrocal_allan::sim::{GyroNoise, generate};

/// Scale factor of the simulated gyro, V/(°/s).
const K: f64 = 0.05;
/// Sample interval, s.
const TAU0: f64 = 0.1;

fn noise() -> GyroNoise {
    GyroNoise {
        bias_deg_per_h: 5.0,
        arw_deg_per_sqrt_h: ARW,
        bias_instability_deg_per_h: B,
        rrw_deg_per_h_per_sqrt_h: RRW,
        ..GyroNoise::default()
    }
}

const ARW: f64 = 0.02;
const B: f64 = 1.0;
const RRW: f64 = 3.0;

/// Writes `n` samples of the simulated gyro as `t_s,volts` (volts = rate/3600·K), with the
/// time jumping by `gap_s` extra seconds after sample `gap_at` when given.
fn write_record(dir: &Path, name: &str, n: usize, seed: u64, gap: Option<(usize, f64)>) -> PathBuf {
    let rate = generate(&noise(), TAU0, n, seed).unwrap();
    let mut s = String::with_capacity(n * 24);
    s.push_str("t_s,volts\n");
    let mut extra = 0.0;
    for (i, r) in rate.iter().enumerate() {
        if let Some((at, g)) = gap
            && i == at
        {
            extra = g;
        }
        let _ = writeln!(s, "{:.3},{:.9e}", i as f64 * TAU0 + extra, r / 3600.0 * K);
    }
    let path = dir.join(name);
    std::fs::write(&path, s).unwrap();
    path
}

fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The five-term fit's ARW, bias instability and RRW each lie within ±2 of their reported
/// standard uncertainties (k = 2, about 95 %) of the values the record was simulated with.
/// (Over seeds 1–8 of this gyro, 21 of the 24 values lie within k = 2 and all within 2.5; the
/// test uses seed 1.) The slope reads are checked for presence and unit only: near a crossing
/// of two terms they carry a bias that their edf-based uncertainty does not include.
#[test]
fn simulated_terms_are_recovered_within_their_uncertainty() {
    let dir = tempfile::tempdir().unwrap();
    let csv = write_record(dir.path(), "drift.csv", 108_000, 1, None);
    let v = json(&gyrocal(&[
        "allan",
        csv.to_str().unwrap(),
        "--scale-factor",
        "0.05",
        "--json",
    ]));
    assert_eq!(v["unit"], "deg/h");
    assert_eq!(v["tau0_s"].as_f64().unwrap(), TAU0);
    assert_eq!(v["segments"].as_array().unwrap().len(), 1);
    let terms = v["noise_terms"]["fit"]["terms"].as_array().unwrap();
    for (name, unit, set) in [
        ("angle_random_walk", "deg/sqrt(h)", ARW),
        ("bias_instability", "deg/h", B),
        ("rate_random_walk", "deg/h/sqrt(h)", RRW),
    ] {
        let t = terms.iter().find(|t| t["term"] == name).unwrap();
        let (x, u) = (
            t["value"]["value"].as_f64().unwrap(),
            t["value"]["uncertainty"].as_f64().unwrap(),
        );
        assert_eq!(t["value"]["unit"], unit);
        assert!(
            (x - set).abs() <= 2.0 * u,
            "{name}: fitted {x} ± {u}, simulated {set}"
        );
    }
    let arw = &v["noise_terms"]["angle_random_walk"];
    assert_eq!(arw["read_at_tau_s"].as_f64().unwrap(), 1.0);
    assert!(
        v["noise_terms"]["bias_instability"]["tau_min_s"]
            .as_f64()
            .unwrap()
            > 1.0
    );
    // bias: 5 °/h simulated; the flicker and random walk make its scatter large
    let bias = v["bias"]["bias"]["value"].as_f64().unwrap();
    assert!((bias - 5.0).abs() < 5.0, "bias {bias}");
    assert!(
        v["bias"]["stability_10s"]["stability"]["value"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert!(v["bias"]["stability_100s"]["windows"].as_u64().unwrap() >= 2);
    assert_eq!(v["warmup"]["window_s"].as_f64().unwrap(), 60.0);
    // every point has its intervals, and the long τ are flagged
    let pts = v["curve"]["points"].as_array().unwrap();
    assert!(pts.iter().any(|p| p["beyond_quarter"] == true));
    for p in pts {
        let d = p["deviation"].as_f64().unwrap();
        assert!(p["ci95"][0].as_f64().unwrap() <= d && d <= p["ci95"][1].as_f64().unwrap());
    }
}

#[test]
fn without_a_scale_factor_the_curve_is_in_volts_and_the_terms_are_not_given() {
    let dir = tempfile::tempdir().unwrap();
    let csv = write_record(dir.path(), "drift.csv", 6_000, 2, None);
    let out = gyrocal(&["allan", csv.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("deviation in V"), "{text}");
    assert!(
        text.contains("need --scale-factor") || text.contains("give --scale-factor"),
        "{text}"
    );
    let v = json(&gyrocal(&["allan", csv.to_str().unwrap(), "--json"]));
    assert!(v["noise_terms"].is_null());
    assert_eq!(v["unit"], "V");
}

#[test]
fn a_gap_splits_the_record_and_the_longest_segment_is_analysed() {
    let dir = tempfile::tempdir().unwrap();
    // 3000 samples, then the recording stops for 100 s and resumes for 9000 more
    let csv = write_record(dir.path(), "gap.csv", 12_000, 3, Some((3_000, 100.0)));
    let v = json(&gyrocal(&[
        "allan",
        csv.to_str().unwrap(),
        "--scale-factor",
        "0.05",
        "--warmup-window",
        "0",
        "--json",
    ]));
    let segs = v["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 2);
    assert_eq!(segs[0]["samples"], 3_000);
    assert_eq!(segs[1]["samples"], 9_000);
    assert_eq!(segs[1]["analysed"], true);
    assert_eq!(segs[0]["analysed"], false);
    // line 1 is the header: sample 3000 is on line 3002
    assert_eq!(segs[1]["lines"][0], 3_002);
    assert_eq!(v["analysed"]["segment"], 1);
    assert_eq!(v["analysed"]["samples"], 9_000);
    assert_eq!(v["curve"]["n_samples"], 9_000);
    assert!(v["warmup"].is_null());
    let out = gyrocal(&["allan", csv.to_str().unwrap(), "--scale-factor", "0.05"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("only the longest is analysed: segment 2 of 2, lines 3002–12001"),
        "{text}"
    );
}

fn bad(args: &[&str]) -> String {
    let out = gyrocal(args);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(err.lines().count(), 1, "{err}");
    err
}

#[test]
fn bad_input_exits_2_naming_the_file_and_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.csv");
    let err = bad(&["allan", missing.to_str().unwrap()]);
    assert!(
        err.contains("nope.csv") && err.contains("no such file"),
        "{err}"
    );

    let no_value = dir.path().join("novalue.csv");
    std::fs::write(&no_value, "t_s,temperature\n0,20\n0.1,20\n").unwrap();
    let err = bad(&["allan", no_value.to_str().unwrap()]);
    assert!(
        err.contains("novalue.csv: line 1") && err.contains("no value column"),
        "{err}"
    );

    let text = dir.path().join("text.csv");
    let mut s = String::from("t_s,volts\n");
    for i in 0..10 {
        let v = if i == 5 {
            "abc".to_string()
        } else {
            format!("0.00{i}")
        };
        let _ = writeln!(s, "{},{v}", f64::from(i) * 0.1);
    }
    std::fs::write(&text, s).unwrap();
    let err = bad(&["allan", text.to_str().unwrap()]);
    assert!(
        err.contains("text.csv: line 7") && err.contains("\"abc\""),
        "{err}"
    );

    let no_time = dir.path().join("notime.csv");
    std::fs::write(&no_time, "value\n1\n2\n3\n4\n").unwrap();
    let err = bad(&["allan", no_time.to_str().unwrap()]);
    assert!(err.contains("--tau0"), "{err}");
    let out = gyrocal(&["allan", no_time.to_str().unwrap(), "--tau0", "1", "--json"]);
    assert!(out.status.success(), "{out:?}");

    let ragged = dir.path().join("ragged.csv");
    std::fs::write(&ragged, "t_s,volts\n0,1\n0.1,2,3\n").unwrap();
    let err = bad(&["allan", ragged.to_str().unwrap()]);
    assert!(err.contains("ragged.csv: line 3"), "{err}");
}

#[test]
fn the_page_has_the_plot_and_the_noise_term_table() {
    let dir = tempfile::tempdir().unwrap();
    let csv = write_record(dir.path(), "drift.csv", 36_000, 4, None);
    let page = dir.path().join("out/page.html");
    let out = gyrocal(&[
        "allan",
        csv.to_str().unwrap(),
        "--scale-factor",
        "0.05",
        "-o",
        page.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(
        html.matches("<svg").count() >= 2,
        "the curve and the warm-up"
    );
    assert!(html.contains("id=\"noise-terms\""));
    assert!(html.contains("angle random walk N"));
    assert!(html.contains("five-term model"));
    assert!(!html.contains("<script"));
}

/// `--streaming` takes the bounded-memory path and prints the same figures: the text differs
/// only in its `memory:` line and the bounded path's note, the JSON only in `memory` and that
/// note. A budget smaller than the record chooses the bounded path by itself.
#[test]
fn streaming_prints_the_same_figures_and_says_the_bounded_path_ran() {
    let dir = tempfile::tempdir().unwrap();
    let csv = write_record(dir.path(), "drift.csv", 30_000, 4, Some((2_000, 3.0)));
    let csv = csv.to_str().unwrap();
    let tmp = dir.path().to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["allan", csv, "--scale-factor", "0.05", "--temp-dir", tmp];
        args.extend_from_slice(extra);
        let out = gyrocal(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    let mem = run(&[]);
    let bounded = run(&["--streaming"]);
    assert!(
        mem.lines()
            .any(|l| l.starts_with("memory: in memory (the record's 30000 samples")),
        "{mem}"
    );
    assert!(
        bounded
            .lines()
            .any(|l| l == "memory: bounded (--streaming)"),
        "{bounded}"
    );
    assert!(
        bounded
            .lines()
            .any(|l| l.starts_with("note: bounded-memory path (--streaming)")),
        "{bounded}"
    );
    let figures = |s: &str| -> Vec<String> {
        s.lines()
            .filter(|l| !l.starts_with("memory:") && !l.starts_with("note: bounded-memory"))
            .map(str::to_string)
            .collect()
    };
    assert_eq!(figures(&mem), figures(&bounded));
    // the figures are there to compare: the curve, the terms, the bias
    assert!(figures(&mem).iter().any(|l| l.starts_with("bias: ")));
    assert!(figures(&mem).len() > 30);

    // the JSON, every figure; a budget below the record's 16 bytes a sample switches by itself
    let a = json(&gyrocal(&[
        "allan",
        csv,
        "--scale-factor",
        "0.05",
        "--json",
        "--estimator",
        "mdev",
    ]));
    let mut b = json(&gyrocal(&[
        "allan",
        csv,
        "--scale-factor",
        "0.05",
        "--json",
        "--estimator",
        "mdev",
        "--max-memory-mib",
        "0",
        "--temp-dir",
        tmp,
    ]));
    assert_eq!(a["memory"]["path"], "in_memory");
    assert_eq!(a["memory"]["budget_bytes"], 1024 * 1024 * 1024);
    assert_eq!(b["memory"]["path"], "bounded");
    assert!(
        b["memory"]["reason"]
            .as_str()
            .unwrap()
            .contains("more than the --max-memory-mib budget of 0 MiB"),
        "{}",
        b["memory"]
    );
    let mut a = a;
    a.as_object_mut().unwrap().remove("memory");
    b.as_object_mut().unwrap().remove("memory");
    b["notes"]
        .as_array_mut()
        .unwrap()
        .retain(|n| !n.as_str().unwrap().starts_with("bounded-memory path"));
    assert_eq!(a, b);
    // nothing left behind in the temporary directory but the record
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}
