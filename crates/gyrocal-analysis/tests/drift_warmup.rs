//! The warm-up an analysis cuts is one the record has: a record whose level only wanders (the
//! simulated bench's gyro: flicker and rate random walk) is not cut, however late its window
//! means first agree; a record that settles from an offset is cut, on both memory paths.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_analysis::drift::{AllanDocument, AllanOptions, analyse_input};

/// τ0 = 1 s, 3 h: 180 windows of the default 60 s.
const TAU0_S: f64 = 1.0;
const ROWS: usize = 3 * 3600;
const SEEDS: u64 = 24;

/// The drift plan's simulated gyro (configs/drift.toml), in °/h.
fn wandering(seed: u64) -> Vec<f64> {
    let noise = GyroNoise {
        bias_deg_per_h: 2.0,
        arw_deg_per_sqrt_h: 0.02,
        bias_instability_deg_per_h: 1.0,
        rrw_deg_per_h_per_sqrt_h: 3.0,
        ..GyroNoise::default()
    };
    generate(&noise, TAU0_S, ROWS, seed).unwrap()
}

/// The same gyro settling from `offset` °/h with time constant `tc_s`.
fn warming(seed: u64, offset: f64, tc_s: f64) -> Vec<f64> {
    let mut v = wandering(seed);
    for (i, y) in v.iter_mut().enumerate() {
        *y += offset * (-(i as f64) * TAU0_S / tc_s).exp();
    }
    v
}

fn write(dir: &Path, name: &str, values: &[f64]) -> PathBuf {
    let mut s = String::from("t_s,rate_dph\n");
    for (i, v) in values.iter().enumerate() {
        let _ = writeln!(s, "{:.1},{v:.9e}", i as f64 * TAU0_S);
    }
    let path = dir.join(name);
    std::fs::write(&path, s).unwrap();
    path
}

fn analyse(path: &Path, streaming: bool) -> AllanDocument {
    analyse_input(
        path,
        &AllanOptions {
            streaming,
            temp_dir: streaming.then(|| path.parent().unwrap().to_path_buf()),
            ..AllanOptions::default()
        },
    )
    .unwrap()
}

fn cut_s(doc: &AllanDocument) -> f64 {
    doc.warmup.as_ref().map_or(0.0, |w| w.time_s)
}

#[test]
fn a_record_that_only_wanders_is_not_cut_and_the_note_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let (mut late, mut cut) = (0, Vec::new());
    for seed in 0..SEEDS {
        let path = write(dir.path(), &format!("w{seed}.csv"), &wandering(seed));
        let doc = analyse(&path, false);
        let w = doc.warmup.as_ref().unwrap();
        // the criterion alone settles late on some of these records: the case of the issue
        if let Some(sig) = &w.significance {
            late += 1;
            if !sig.significant {
                assert_eq!((w.time_s, w.ended_by.as_str()), (0.0, "not_significant"));
                assert!(
                    doc.notes.iter().any(|n| n.starts_with("no warm-up:")),
                    "{:?}",
                    doc.notes
                );
            }
        }
        if cut_s(&doc) > 0.0 {
            cut.push((seed, cut_s(&doc)));
        }
    }
    eprintln!(
        "criterion alone cut {late} of {SEEDS} records with no warm-up; after the test: {}",
        cut.len()
    );
    assert!(
        late >= 3,
        "the criterion settled late on only {late} of {SEEDS} records: the test shows nothing"
    );
    // 3 × a robust σ: a stationary record is cut about once in a few hundred tests
    assert!(cut.len() <= 1, "records with no warm-up were cut: {cut:?}");
}

#[test]
fn a_record_that_settles_from_an_offset_is_cut_on_both_paths() {
    let dir = tempfile::tempdir().unwrap();
    for seed in 0..SEEDS / 4 {
        // 40 °/h settling with a 10 min time constant (the gyro's wander is about 1 °/h at a
        // minute, so the criterion may settle well before the offset has died away)
        let path = write(
            dir.path(),
            &format!("h{seed}.csv"),
            &warming(seed, 40.0, 600.0),
        );
        let doc = analyse(&path, false);
        let w = doc.warmup.as_ref().unwrap();
        assert_eq!(w.ended_by, "criterion", "seed {seed}: {:?}", doc.notes);
        assert!(w.time_s >= 60.0, "seed {seed}: cut {} s", w.time_s);
        assert!(w.significance.as_ref().unwrap().significant);
        assert!(
            doc.notes
                .iter()
                .any(|n| n.contains("is more than the record's own wander")),
            "{:?}",
            doc.notes
        );
        let bounded = analyse(&path, true);
        assert_eq!(bounded.warmup, doc.warmup, "seed {seed}");
    }
}
