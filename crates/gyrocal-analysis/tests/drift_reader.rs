//! The Allan analysis reads its record with the chunked reader (blocks of 1 MiB parsed in
//! parallel): on a record of several blocks, the figures do not depend on how the file is
//! written (LF or CRLF, a byte-order mark, comment lines), the bounded path gives the in-memory
//! document, and an error far into the file names its line as the line reader did, with the
//! same message.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_analysis::drift::{AllanDocument, AllanOptions, WarmupOptions, analyse_input};

/// 80 000 rows of `t_s,volts` (about 1.8 MB: two blocks of the reader), τ0 = 0.1 s.
const ROWS: usize = 80_000;

fn values() -> Vec<f64> {
    let noise = GyroNoise {
        bias_deg_per_h: 3.0,
        arw_deg_per_sqrt_h: 0.05,
        bias_instability_deg_per_h: 0.2,
        ..GyroNoise::default()
    };
    generate(&noise, 0.1, ROWS, 11).unwrap()
}

/// The record written with `eol`, a byte-order mark and a comment every 10 000 rows when
/// `decorated`; `edit` may change a row's text.
fn write(
    dir: &Path,
    name: &str,
    eol: &str,
    decorated: bool,
    edit: impl Fn(usize, String) -> String,
) -> PathBuf {
    let mut s = String::new();
    if decorated {
        s.push('\u{feff}');
        let _ = write!(s, "# a logger's note{eol}");
    }
    let _ = write!(s, "t_s,volts{eol}");
    for (i, v) in values().iter().enumerate() {
        if decorated && i % 10_000 == 0 {
            let _ = write!(s, "# block {i}, with a comma, and \"quotes\"{eol}");
        }
        let row = edit(
            i,
            format!("{:.1},{:.10e}", i as f64 * 0.1, v / 3600.0 * 0.02),
        );
        let _ = write!(s, "{row}{eol}");
    }
    let path = dir.join(name);
    std::fs::write(&path, s).unwrap();
    path
}

fn opts() -> AllanOptions {
    AllanOptions {
        warmup: WarmupOptions {
            window_s: 0.0,
            ..WarmupOptions::default()
        },
        ..AllanOptions::default()
    }
}

/// The figures of a document (not the lines, which the comments shift).
fn figures(doc: &AllanDocument) -> serde_json::Value {
    let v = serde_json::to_value(doc).unwrap();
    serde_json::json!({
        "rows": v["rows"],
        "tau0_s": v["tau0_s"],
        "curve": v["curve"],
        "noise_terms": v["noise_terms"],
        "bias": v["bias"],
        "samples": v["analysed"]["samples"],
    })
}

#[test]
fn the_figures_do_not_depend_on_line_ends_marks_or_comments() {
    let dir = tempfile::tempdir().unwrap();
    let plain = write(dir.path(), "plain.csv", "\n", false, |_, r| r);
    let windows = write(dir.path(), "windows.csv", "\r\n", true, |_, r| r);
    // more than one block of the reader (1 MiB): two are parsed at once
    assert!(std::fs::metadata(&plain).unwrap().len() > 1024 * 1024);
    let a = analyse_input(&plain, &opts()).unwrap();
    let b = analyse_input(&windows, &opts()).unwrap();
    assert_eq!(a.rows, ROWS as u64);
    assert_eq!(figures(&a), figures(&b));
    // the lines counted through the comments: the last row of the decorated file
    let last = b.segments.last().unwrap().lines.1;
    assert_eq!(last, 2 + ROWS as u64 + (ROWS as u64).div_ceil(10_000));
    // the bounded path reads the same blocks into its temporary file: the same figures
    let bounded = analyse_input(
        &windows,
        &AllanOptions {
            streaming: true,
            temp_dir: Some(dir.path().to_path_buf()),
            ..opts()
        },
    )
    .unwrap();
    assert_eq!(figures(&bounded), figures(&b));
}

#[test]
fn an_error_far_into_the_file_names_its_line() {
    let dir = tempfile::tempdir().unwrap();
    // row 70 000 is line 70 002 (the header is line 1)
    let bad = write(dir.path(), "bad.csv", "\n", false, |i, r| {
        if i == 70_000 { "7000.0,x".into() } else { r }
    });
    let e = analyse_input(&bad, &opts()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: line 70002: `volts` is not a number: \"x\"",
            bad.display()
        )
    );
    let empty = write(dir.path(), "empty.csv", "\n", false, |i, r| {
        if i == 65_432 { "6543.2,".into() } else { r }
    });
    let e = analyse_input(&empty, &opts()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!("{}: line 65434: `volts` is empty", empty.display())
    );
    let back = write(dir.path(), "back.csv", "\n", false, |i, r| {
        if i == 50_000 {
            "4000.0,0.001".into()
        } else {
            r
        }
    });
    let e = analyse_input(&back, &opts()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: line 50002: the time does not increase (4000 s after 4999.9 s)",
            back.display()
        )
    );
    let short = write(dir.path(), "short.csv", "\n", false, |i, r| {
        if i == 79_999 { "7999.9".into() } else { r }
    });
    let e = analyse_input(&short, &opts()).unwrap_err();
    assert_eq!(
        e.to_string(),
        format!(
            "{}: line 80001: expected 2 fields like the header, found 1",
            short.display()
        )
    );
}
