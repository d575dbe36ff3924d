//! The bounded-memory path of the Allan analysis gives the in-memory path's document, bit for
//! bit: every point (τ, σ, terms, EDF, intervals, noise type), the noise terms, the bias
//! figures, the warm-up, the segments, τ0 — for every estimator and τ set, forced
//! (`streaming`) or chosen by the memory budget.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use gyrocal_allan::sim::{GyroNoise, generate};
use gyrocal_allan::{Estimator, TauSet};
use gyrocal_analysis::drift::{
    AllanDocument, AllanOptions, AnalysisPath, WarmupOptions, analyse_input,
};

const K: f64 = 0.02;
const TAU0: f64 = 0.1;

/// A CSV `t_s,volts,overload` of `n` readings: the output `warm` °/h high at first, settling
/// with a 60 s time constant; an overload row at `overload`; the time jumping by 5 s after
/// sample `gap` (a second, shorter segment before it).
fn csv(dir: &Path, n: usize, warm: f64, overload: usize, gap: usize, seed: u64) -> PathBuf {
    let noise = GyroNoise {
        bias_deg_per_h: 7.0,
        quantization_arcsec: 0.3,
        arw_deg_per_sqrt_h: 0.05,
        bias_instability_deg_per_h: 0.5,
        rrw_deg_per_h_per_sqrt_h: 2.0,
        ..GyroNoise::default()
    };
    let rate = generate(&noise, TAU0, n, seed).unwrap();
    let mut s = String::from("t_s,volts,overload\n");
    for (i, r) in rate.iter().enumerate() {
        let t = i as f64 * TAU0 + if i >= gap { 5.0 } else { 0.0 };
        let r = r + warm * (-(i as f64 * TAU0) / 60.0).exp();
        if i == overload {
            let _ = writeln!(s, "{t:.3},,1");
        } else {
            let _ = writeln!(s, "{t:.3},{:.10e},0", r / 3600.0 * K);
        }
    }
    let path = dir.join(format!("record-{seed}.csv"));
    std::fs::write(&path, s).unwrap();
    path
}

/// The document as JSON (f64 written as the shortest text that reads back to the same bits),
/// without what differs by design: the path taken and its note.
fn comparable(doc: &AllanDocument) -> serde_json::Value {
    let mut v = serde_json::to_value(doc).unwrap();
    let o = v.as_object_mut().unwrap();
    o.remove("memory");
    o["notes"]
        .as_array_mut()
        .unwrap()
        .retain(|n| !n.as_str().unwrap().starts_with("bounded-memory path"));
    v
}

fn both(path: &Path, opts: &AllanOptions) -> (AllanDocument, AllanDocument) {
    let mem = analyse_input(path, opts).unwrap();
    let bounded = analyse_input(
        path,
        &AllanOptions {
            streaming: true,
            ..opts.clone()
        },
    )
    .unwrap();
    assert_eq!(mem.memory.path, AnalysisPath::InMemory);
    assert_eq!(bounded.memory.path, AnalysisPath::Bounded);
    assert_eq!(bounded.memory.reason, "--streaming");
    assert!(
        bounded
            .notes
            .iter()
            .any(|n| n.starts_with("bounded-memory path (--streaming)"))
    );
    assert!(!mem.notes.iter().any(|n| n.starts_with("bounded-memory")));
    assert_eq!(
        comparable(&mem),
        comparable(&bounded),
        "{:?} {:?}",
        opts.estimator,
        opts.taus
    );
    (mem, bounded)
}

#[test]
fn every_estimator_gives_the_same_document_on_both_paths() {
    let tmp = tempfile::tempdir().unwrap();
    // warm-up, an overload (a gap) and a time jump: three segments, the warm-up cut
    let path = csv(tmp.path(), 24_000, 200.0, 200, 300, 1);
    for est in Estimator::ALL {
        let opts = AllanOptions {
            scale_factor: Some(K),
            estimator: est,
            ..AllanOptions::default()
        };
        let (mem, _) = both(&path, &opts);
        // the record really has what the comparison must cover
        assert_eq!(mem.segments.len(), 3);
        assert!(mem.analysed.warmup_samples > 0, "{:?}", mem.warmup);
        assert!(mem.curve.points.len() > 8);
        assert!(mem.noise_terms.as_ref().unwrap().fit.is_some());
        assert!(mem.bias.stability_100s.is_some());
    }
    for taus in [
        TauSet::Decade,
        TauSet::PerDecade(5),
        TauSet::Explicit(vec![0.3, 7.7, 42.0]),
    ] {
        let opts = AllanOptions {
            scale_factor: Some(K),
            taus,
            ..AllanOptions::default()
        };
        both(&path, &opts);
    }
}

#[test]
fn every_tau_and_the_warm_up_options_match_on_a_short_record() {
    let tmp = tempfile::tempdir().unwrap();
    let path = csv(tmp.path(), 2_600, 40.0, 2_000, 2_600, 2);
    for est in Estimator::ALL {
        let opts = AllanOptions {
            scale_factor: Some(K),
            estimator: est,
            taus: TauSet::All,
            warmup: WarmupOptions {
                window_s: 10.0,
                ..WarmupOptions::default()
            },
            ..AllanOptions::default()
        };
        both(&path, &opts);
    }
    // a tolerance given, a cap, no warm-up, one sample a window, the volts unscaled
    for warmup in [
        WarmupOptions {
            window_s: 20.0,
            tolerance: Some(1e-6),
            max_s: None,
        },
        WarmupOptions {
            window_s: 20.0,
            tolerance: Some(1e-12),
            max_s: Some(33.0),
        },
        WarmupOptions {
            window_s: 20.0,
            tolerance: Some(1e-12),
            max_s: None,
        },
        WarmupOptions {
            window_s: 0.0,
            ..WarmupOptions::default()
        },
        WarmupOptions {
            window_s: 0.1,
            ..WarmupOptions::default()
        },
    ] {
        let opts = AllanOptions {
            warmup,
            ..AllanOptions::default()
        };
        let (mem, _) = both(&path, &opts);
        assert_eq!(mem.unit, "V");
    }
}

#[test]
fn the_budget_chooses_the_path_and_the_figures_stay() {
    let tmp = tempfile::tempdir().unwrap();
    let path = csv(tmp.path(), 12_000, 0.0, usize::MAX, usize::MAX, 3);
    let opts = |budget: u64| AllanOptions {
        scale_factor: Some(K),
        max_memory_bytes: Some(budget),
        temp_dir: Some(tmp.path().to_path_buf()),
        ..AllanOptions::default()
    };
    // 12 000 samples at 16 bytes = 192 000 bytes
    let fits = analyse_input(&path, &opts(192_000)).unwrap();
    assert_eq!(fits.memory.path, AnalysisPath::InMemory);
    assert_eq!(fits.memory.record_samples, 12_000);
    let over = analyse_input(&path, &opts(191_999)).unwrap();
    assert_eq!(over.memory.path, AnalysisPath::Bounded);
    assert!(
        over.memory
            .reason
            .contains("more than the --max-memory-mib budget"),
        "{}",
        over.memory.reason
    );
    assert!(
        over.notes
            .iter()
            .any(|n| n.starts_with("bounded-memory path (the record's 12000 samples")),
        "{:?}",
        over.notes
    );
    assert_eq!(comparable(&fits), comparable(&over));
    // the temporary files are gone
    let left: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 1, "{left:?}");

    // without a time column (no pass 1) the values alone decide
    let mut s = String::from("value\n");
    for line in std::fs::read_to_string(&path).unwrap().lines().skip(1) {
        let _ = writeln!(s, "{}", line.split(',').nth(1).unwrap());
    }
    let bare = tmp.path().join("bare.csv");
    std::fs::write(&bare, s).unwrap();
    let opts = AllanOptions {
        tau0_s: Some(TAU0),
        ..AllanOptions::default()
    };
    let (mem, _) = both(&bare, &opts);
    assert_eq!(mem.tau0_source, "option");
}

#[test]
fn a_missing_temporary_directory_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let path = csv(tmp.path(), 500, 0.0, usize::MAX, usize::MAX, 4);
    let nowhere = tmp.path().join("no-such-dir");
    let e = analyse_input(
        &path,
        &AllanOptions {
            streaming: true,
            temp_dir: Some(nowhere.clone()),
            ..AllanOptions::default()
        },
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains(&nowhere.display().to_string()), "{msg}");
    assert!(msg.contains("temporary file"), "{msg}");
    assert!(msg.contains("no such directory"), "{msg}");
    // a directory the user named is their input to fix (exit 2), checked before the record
    assert!(e.is_input_error());
}
