//! A record with a short gap (a resume's 38 s in 3 h) is analysed by its longest segment and
//! the analysis says how to analyse it whole; the value it gives joins the record into one; a
//! long break is not suggested for joining.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_analysis::drift::{AllanOptions, WarmupOptions, analyse_input};

const ROWS: usize = 3 * 3600;

/// 3 h at τ0 = 1 s with a gap of `gap_s` after the first hour.
fn write(dir: &Path, name: &str, gap_s: f64) -> PathBuf {
    let noise = GyroNoise {
        arw_deg_per_sqrt_h: 0.05,
        bias_instability_deg_per_h: 0.2,
        ..GyroNoise::default()
    };
    let v = generate(&noise, 1.0, ROWS, 5).unwrap();
    let mut s = String::from("t_s,rate_dph\n");
    for (i, y) in v.iter().enumerate() {
        let t = i as f64 + if i >= 3600 { gap_s } else { 0.0 };
        let _ = writeln!(s, "{t:.1},{y:.9e}");
    }
    let path = dir.join(name);
    std::fs::write(&path, s).unwrap();
    path
}

fn opts(join: Option<f64>) -> AllanOptions {
    AllanOptions {
        join_gaps_below_s: join,
        warmup: WarmupOptions {
            window_s: 0.0,
            ..WarmupOptions::default()
        },
        ..AllanOptions::default()
    }
}

#[test]
fn a_short_gap_is_said_with_the_value_that_joins_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "resumed.csv", 38.0);
    let doc = analyse_input(&path, &opts(None)).unwrap();
    assert_eq!(doc.segments.len(), 2);
    assert_eq!(doc.analysed.samples, ROWS - 3600);
    // 38 s missing: an interval of 39 s between two samples; 40 joins it
    assert_eq!(doc.join_gaps_hint_s, Some(40.0));
    assert!(
        doc.notes
            .iter()
            .any(|n| n.contains("give --join-gaps-below 40")),
        "{:?}",
        doc.notes
    );
    // the value given back joins the record: one segment, every sample analysed, no hint
    let joined = analyse_input(&path, &opts(doc.join_gaps_hint_s)).unwrap();
    assert_eq!(joined.segments.len(), 1);
    assert_eq!(joined.analysed.samples, ROWS);
    assert_eq!(joined.join_gaps_hint_s, None);
}

#[test]
fn a_long_break_is_not_suggested_for_joining() {
    let dir = tempfile::tempdir().unwrap();
    // half an hour off in 3 h: the gyro may have been switched off or moved
    let path = write(dir.path(), "break.csv", 1800.0);
    let doc = analyse_input(&path, &opts(None)).unwrap();
    assert_eq!(doc.segments.len(), 2);
    assert_eq!(doc.join_gaps_hint_s, None);
    assert!(!doc.notes.iter().any(|n| n.contains("--join-gaps-below")));
}
