//! `gyrocal fit` as a user runs it: output, JSON, and one-line errors with exit code 2.

// Helpers outside #[test] functions may unwrap too: a panic there is a failed test.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};

/// `gyrocal ARGS` run to its end, through tests/common.
use common::gyrocal_output as gyrocal;

fn example() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/paper-shaped.csv")
}

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> String {
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn json_is_one_document_with_every_fit_and_the_metrics() {
    let out = gyrocal(&["fit", "--json", example().to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    assert_eq!(v["points"], 19);
    let fits = v["fits"].as_array().unwrap();
    let names: Vec<String> = fits
        .iter()
        .map(|f| {
            format!(
                "{} {}",
                f["method"].as_str().unwrap(),
                f["model"].as_str().unwrap()
            )
        })
        .collect();
    assert_eq!(
        names,
        [
            "least-squares linear",
            "least-squares quadratic",
            "least-squares cubic",
            "least-squares split",
            "neuron linear"
        ]
    );
    let k = fits[0]["scale_factor"].as_f64().unwrap();
    assert!((k - 0.3612).abs() < 1e-4, "{k}");
    let kn = fits[4]["scale_factor"].as_f64().unwrap();
    assert!(((kn - k) / k).abs() < 1e-6);
    assert_eq!(fits[4]["converged"], true);
    assert!(v["metrics"]["asymmetry_ppm"].is_number());
    assert!(v["metrics"]["repeatability_ppm"].is_null());
}

#[test]
fn human_report_has_the_table_and_an_honest_comparison() {
    let out = gyrocal(&["fit", example().to_str().unwrap()]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("LS resid. [mV]") && text.contains("neuron resid. [mV]"),
        "{text}"
    );
    assert!(text.contains("same estimate, not a better one"), "{text}");
    assert!(!text.contains("neuron is better"));
    // 19 table rows: every rate appears at the start of a line.
    for rate in ["-20", "-0.1", "0", "0.7", "20"] {
        assert!(
            text.lines()
                .any(|l| l.trim_start().starts_with(&format!("{rate} "))),
            "{rate}"
        );
    }
}

#[test]
fn selected_model_and_method_only() {
    let out = gyrocal(&[
        "fit",
        "--json",
        "--model",
        "quadratic",
        "--method",
        "least-squares",
        example().to_str().unwrap(),
    ]);
    assert!(out.status.success());
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    let fits = v["fits"].as_array().unwrap();
    assert_eq!(fits.len(), 1);
    assert_eq!(fits[0]["model"], "quadratic");
    assert!(fits[0]["coefficients"]["k2"].is_number());
}

#[test]
fn huge_learning_rate_says_diverged() {
    let out = gyrocal(&[
        "fit",
        "--method",
        "neuron",
        "--eta",
        "100",
        example().to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("DIVERGED"), "{text}");
    assert!(!text.contains("NaN"));
}

#[test]
fn several_files_report_repeatability() {
    let dir = tempfile::tempdir().unwrap();
    let a = write(
        &dir,
        "a.csv",
        "rate_dps,volts\n-10,-3.6032\n0,0.0088\n10,3.6208\n",
    );
    let b = write(
        &dir,
        "b.csv",
        "rate_dps,volts\n-10,-3.6042\n0,0.0088\n10,3.6218\n",
    );
    let out = gyrocal(&["fit", "--json", &a, &b]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["files"].as_array().unwrap().len(), 2);
    let r = v["repeatability_ppm"].as_f64().unwrap();
    // K = 0.3612 and 0.3613: std/mean = (1e-4/√2)/0.36125.
    assert!((r - 1e-4 / 2f64.sqrt() / 0.36125 * 1e6).abs() < 1.0, "{r}");
}

/// Runs `gyrocal fit` on a file and checks: exit code 2, one line on stderr naming the file
/// and the line, containing `needle`, nothing on stdout.
fn bad(text: &str, extra: &[&str], line: u64, needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let path = write(&dir, "bad.csv", text);
    let mut args = vec!["fit"];
    args.extend_from_slice(extra);
    args.push(&path);
    let out = gyrocal(&args);
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(out.stdout.is_empty());
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains(&format!("{path}: line {line}")), "{err}");
    assert!(err.contains(needle), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn missing_file() {
    let out = gyrocal(&["fit", "/nonexistent/gyro.csv"]);
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(err.trim_end().lines().count(), 1);
    assert!(err.contains("/nonexistent/gyro.csv: cannot open"), "{err}");
}

#[test]
fn missing_column() {
    bad(
        "# rate table run\nrate_dps,voltage\n0,0.0088\n1,0.37\n",
        &[],
        2,
        "no `volts` column",
    );
}

#[test]
fn non_numeric_value() {
    bad(
        "rate_dps,volts\n0,0.0088\n1,0.3.7\n2,0.73\n",
        &[],
        3,
        "not a number",
    );
}

#[test]
fn nan_value() {
    bad(
        "rate_dps,volts\n0,0.0088\n1,NaN\n2,0.73\n",
        &[],
        3,
        "not a finite number",
    );
}

#[test]
fn infinite_value() {
    bad(
        "rate_dps,volts\n0,0.0088\n1,0.37\n-inf,0.73\n",
        &[],
        4,
        "not a finite number",
    );
}

#[test]
fn fewer_points_than_coefficients() {
    bad(
        "rate_dps,volts\n0,0.0088\n1,0.37\n2,0.73\n",
        &["--model", "cubic"],
        4,
        "the cubic model has 4 coefficients and needs at least 4 distinct rates; the data have 3",
    );
}

#[test]
fn fewer_than_two_distinct_rates() {
    bad(
        "rate_dps,volts\n1,0.37\n1,0.371\n1,0.369\n",
        &[],
        4,
        "1 distinct rate",
    );
}

#[test]
fn split_without_both_signs() {
    bad(
        "rate_dps,volts\n0,0.0088\n1,0.37\n2,0.73\n",
        &["--model", "split"],
        4,
        "negative side",
    );
}

#[test]
fn three_rates_skip_the_cubic_model_with_the_reason_and_exit_0() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = write(
        &tmp,
        "three.csv",
        "rate_dps,volts\n0,0.0088\n10,3.6208\n-10,-3.6032\n10,3.6211\n-10,-3.6030\n0,0.0091\n",
    );
    let out = gyrocal(&["fit", "--json", &csv]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    let skipped = v["skipped"].as_array().unwrap();
    assert_eq!(skipped.len(), 1, "{skipped:?}");
    assert_eq!(skipped[0]["model"], "cubic");
    let reason = skipped[0]["reason"].as_str().unwrap();
    assert!(
        reason.contains("4 coefficients") && reason.contains("the data have 3"),
        "{reason}"
    );
    let models: Vec<&str> = v["fits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["model"].as_str().unwrap())
        .collect();
    assert!(!models.contains(&"cubic"), "{models:?}");
    let out = gyrocal(&["fit", &csv]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("not fitted: cubic — the cubic model has 4 coefficients"),
        "{text}"
    );
}

#[test]
fn one_direction_skips_split_and_says_why_asymmetry_is_missing() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = write(
        &tmp,
        "up.csv",
        "rate_dps,volts\n0,0.0088\n1,0.3700\n5,1.8148\n10,3.6208\n20,7.2328\n",
    );
    let out = gyrocal(&["fit", "--json", &csv]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    assert_eq!(v["skipped"][0]["model"], "split");
    assert!(
        v["skipped"][0]["reason"]
            .as_str()
            .unwrap()
            .contains("negative side")
    );
    assert!(v["metrics"]["asymmetry_ppm"].is_null());
    let nc = v["metrics"]["not_computed"].as_array().unwrap();
    assert!(
        nc.iter().any(|n| n["metric"] == "asymmetry_ppm"
            && n["reason"].as_str().unwrap().contains("turning directions")),
        "{nc:?}"
    );
    let out = gyrocal(&["fit", &csv]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("not fitted: split — "), "{text}");
    assert!(
        text.contains("asymmetry             not computed: needs the split model"),
        "{text}"
    );
}

#[test]
fn a_model_asked_for_by_name_that_the_data_cannot_determine_exits_2() {
    bad(
        "rate_dps,volts\n0,0.0088\n10,3.6208\n-10,-3.6032\n10,3.6211\n",
        &["--model", "cubic"],
        5,
        "asked for with --model",
    );
}

#[test]
fn a_duplicated_column_exits_2_naming_both() {
    bad(
        "rate_dps,volts,VOLTS\n0,0.0088,1\n1,0.37,1\n",
        &[],
        1,
        "column `VOLTS` twice (columns 2 and 3)",
    );
}

#[test]
fn endless_and_huge_inputs_exit_2_quickly() {
    let started = std::time::Instant::now();
    // a device is refused before it is read
    let out = gyrocal(&["fit", "/dev/zero"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("/dev/zero: a device, not a regular file"),
        "{err}"
    );
    // A large file without line breaks is refused after its first MiB (sparse: no disk used).
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("huge.csv");
    let f = std::fs::File::create(&path).unwrap();
    f.set_len(64 * 1024 * 1024 + 1).unwrap();
    let out = gyrocal(&["fit", path.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("huge.csv: line 1: longer than"), "{err}");
    assert!(
        started.elapsed() < std::time::Duration::from_secs(30),
        "{:?}",
        started.elapsed()
    );
}

#[test]
fn many_points_get_per_rate_summaries_unless_residuals_is_given() {
    let tmp = tempfile::tempdir().unwrap();
    let rates = [-20.0, -10.0, -1.0, 0.0, 1.0, 10.0, 20.0];
    let mut text = String::from("rate_dps,volts\n");
    for i in 0..14_000 {
        let w = rates[(i * 5) % rates.len()];
        let noise = 1e-4 * ((i as f64 * 0.618_033_988_7).fract() - 0.5);
        text.push_str(&format!(
            "{w},{}\n",
            0.0088 + 0.3612 * w + 2e-6 * w * w + noise
        ));
    }
    let path = write(&tmp, "many.csv", &text);
    let out = gyrocal(&["fit", "--json", &path]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    assert_eq!(v["points"], 14_000);
    assert_eq!(v["distinct_rates"], 7);
    assert_eq!(v["residual_detail"], "per-rate");
    for f in v["fits"].as_array().unwrap() {
        assert_eq!(f["residuals"].as_array().unwrap().len(), 0);
        let rr = f["rate_residuals"].as_array().unwrap();
        assert_eq!(rr.len(), 7);
        assert_eq!(
            rr.iter().map(|r| r["n"].as_u64().unwrap()).sum::<u64>(),
            14_000
        );
    }
    let nn = &v["fits"][4];
    assert_eq!(nn["method"], "neuron");
    assert_eq!(nn["neuron"]["training_data"]["kind"], "rate-means");
    assert_eq!(nn["neuron"]["training_data"]["rates"], 7);
    let (ls, nsse) = (
        v["fits"][0]["sse"].as_f64().unwrap(),
        nn["sse"].as_f64().unwrap(),
    );
    assert!((nsse - ls).abs() <= 1e-9 * ls, "{nsse} vs {ls}");

    let out = gyrocal(&["fit", "--json", "--residuals", &path]);
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let v = serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()["files"][0].take();
    assert_eq!(v["residual_detail"], "per-point");
    assert_eq!(v["fits"][0]["residuals"].as_array().unwrap().len(), 14_000);

    let out = gyrocal(&["fit", &path]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("online passes on the means of the 7 rates"),
        "{text}"
    );
    assert!(text.contains("LS mean r. [mV]"), "{text}");
    assert!(text.lines().count() < 60, "{text}");
}

/// `gyrocal fit RUN_DIR` fits the run's steps (its steps.csv), the same as naming the file;
/// a directory that is no run is refused saying what to give, not "cannot read: Is a
/// directory".
#[test]
fn a_run_directory_is_fitted_by_its_steps_and_another_directory_is_refused_in_words() {
    let tmp = tempfile::tempdir().unwrap();
    let run = common::fixture_rundir("sweep-complete", tmp.path());
    let steps = run.join("steps.csv");
    let by_dir = gyrocal(&["fit", run.to_str().unwrap(), "--json"]);
    assert_eq!(
        by_dir.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&by_dir.stderr)
    );
    let by_file = gyrocal(&["fit", steps.to_str().unwrap(), "--json"]);
    let k = |o: &std::process::Output| {
        // one file: the first of `files` (fit --json has one shape for any number of files)
        let doc =
            serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()["files"][0].take();
        doc["metrics"]["scale_factor"].as_f64().unwrap()
    };
    assert_eq!(k(&by_dir), k(&by_file));

    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let o = gyrocal(&["fit", empty.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("a directory without steps.csv"), "{err}");
    assert!(!err.contains("Is a directory"), "{err}");
}
