//! Run directories written by an earlier release still load, resume, verify and report: the
//! fixtures under `tests/fixtures/rundirs/` (written by release 56e032e with
//! `tests/fixtures/rundirs/make.sh`, see the README there) are copied to a temporary directory
//! and driven through the binary as an operator would. An interrupted sweep and an
//! interrupted drift record resume to completion on the simulated bench (the table ends at
//! rest, nothing is lost or doubled, samples.csv's kept rows stay byte for byte and the new
//! ones are in its own columns, `step` and `index` counted from 0; steps.csv is rewritten in
//! format 3, its kept rows' `step` and `pass` become `step_no` and `pass_no` plus one, every
//! other cell as it was), then `gyrocal verify` passes and `gyrocal report` renders; the
//! complete sweep verifies and reports as it is, and its `fit.json` is the fit `gyrocal fit`
//! computes again from its `steps.csv`.
//!
//! These are the compatibility net of a restructuring: they must pass unchanged on every
//! later release that keeps the run directory's format. (Format 3, which counts from 1 in the
//! CSV files, changed the two things a resume does to steps.csv and these tests say so.)

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::collections::BTreeSet;
use std::path::Path;

use common::{RunOutput, final_table_state, fixture_rundir, gyrocal, json, run_json};

/// `(step, index)` of every row of samples.csv, and the run clock `t_s` of each, in file order:
/// the earlier release's columns, counted from 0 (a resume keeps appending rows of the file's
/// own columns).
fn samples(dir: &Path) -> Vec<((u64, u64), f64)> {
    let mut r = csv::Reader::from_path(dir.join("samples.csv")).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |name: &str| h.iter().position(|c| c == name).unwrap();
    let (s, i, t) = (col("step"), col("index"), col("t_s"));
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            (
                (rec[s].parse().unwrap(), rec[i].parse().unwrap()),
                rec[t].parse().unwrap(),
            )
        })
        .collect()
}

/// The steps of steps.csv, 0-based, in file order: a resume rewrote it in format 3, whose
/// first column is `step_no`, counted from 1.
fn steps(dir: &Path) -> Vec<u64> {
    let mut r = csv::Reader::from_path(dir.join("steps.csv")).unwrap();
    assert_eq!(&r.headers().unwrap()[0], "step_no");
    r.records()
        .map(|rec| rec.unwrap()[0].parse::<u64>().unwrap() - 1)
        .collect()
}

/// The fixture's steps.csv rows are the first rows of the resumed run's, converted to format
/// 3: `step_no` and `pass_no` are its `step` and `pass` plus one, every other cell as it was.
fn kept_converted(fixture: &str, dir: &Path) {
    let before = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/fixtures/rundirs")
            .join(fixture)
            .join("steps.csv"),
    )
    .unwrap();
    let after = std::fs::read_to_string(dir.join("steps.csv")).unwrap();
    let (old, new): (Vec<&str>, Vec<&str>) = (before.lines().collect(), after.lines().collect());
    assert!(old[0].starts_with("step,pass,"), "{}", old[0]);
    assert_eq!(
        new[0],
        old[0].replacen("step,pass,", "step_no,pass_no,", 1),
        "{fixture}: the header"
    );
    assert!(new.len() > old.len(), "{fixture}: rows appended");
    for (o, n) in old.iter().zip(&new).skip(1) {
        let (o, n): (Vec<&str>, Vec<&str>) = (o.split(',').collect(), n.split(',').collect());
        for k in 0..2 {
            let was: u64 = o[k].parse().unwrap();
            assert_eq!(n[k], (was + 1).to_string(), "{fixture}: {o:?} became {n:?}");
        }
        assert_eq!(
            o[2..],
            n[2..],
            "{fixture}: the other cells are kept as they were"
        );
    }
}

/// The fixture's `file` is kept byte for byte at the start of the resumed run's `file`.
fn kept_as_prefix(fixture: &str, dir: &Path, file: &str) {
    let before = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/fixtures/rundirs")
            .join(fixture)
            .join(file),
    )
    .unwrap();
    let after = std::fs::read(dir.join(file)).unwrap();
    assert!(
        after.len() > before.len() && after.starts_with(&before),
        "{fixture}/{file}: the rows the earlier release wrote are not kept as they were"
    );
}

/// A complete run: every step once in order, `per_step` readings each, no (step, index)
/// twice, and a run clock that never goes back (a resume continues it).
fn check_complete_data(dir: &Path, steps_total: u64, per_step: u64) {
    assert_eq!(steps(dir), (0..steps_total).collect::<Vec<_>>());
    let s = samples(dir);
    assert_eq!(s.len() as u64, steps_total * per_step, "no reading lost");
    let keys: BTreeSet<(u64, u64)> = s.iter().map(|(k, _)| *k).collect();
    assert_eq!(keys.len(), s.len(), "no reading doubled");
    for w in s.windows(2) {
        assert!(w[1].1 > w[0].1, "t_s goes back: {:?} then {:?}", w[0], w[1]);
    }
}

/// `gyrocal verify DIR`: exit 0, each of `files` said to be ok.
fn verify_passes(dir: &Path, files: &[&str]) {
    let o = gyrocal().arg("verify").arg(dir).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{out}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for f in files {
        assert!(out.contains(&format!("{f} ok")), "{f} ok in:\n{out}");
    }
}

/// `gyrocal report --json DIR`: exit 0; returns its JSON document.
fn report(dir: &Path) -> serde_json::Value {
    let o = gyrocal()
        .args(["report", "--json"])
        .arg(dir)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

/// A resumed session on the simulated bench that completes the run with the table at rest
/// (both as the run's JSON says and as the simulated table itself ended).
fn resume_to_completion(dir: &Path) -> RunOutput {
    let out = run_json(&[&"--simulate", &"--resume", &dir]);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    assert_eq!(out.doc["status"], "complete", "{}", out.doc);
    assert_eq!(out.doc["table"]["at_rest"], true, "{}", out.doc["table"]);
    let end = final_table_state(&out.stderr);
    assert_eq!(end["stopped"], true, "{end}");
    assert_eq!(end["mode"], "Off", "{end}");
    assert_eq!(end["demanded_dps"], 0.0, "{end}");
    out
}

#[test]
fn an_interrupted_sweep_of_the_earlier_release_resumes_verifies_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = fixture_rundir("sweep-interrupted", tmp.path());
    let before = json(&dir, "manifest.json");
    assert_eq!(before["status"], "failed");
    assert_eq!(before["steps_done"], serde_json::json!([0, 1]));

    let out = resume_to_completion(&dir);
    assert!(
        out.stderr.contains("2 of 5 steps done, 3 to go"),
        "{}",
        out.stderr
    );
    assert_eq!(out.doc["steps_recorded_this_session"], 3, "{}", out.doc);
    let m = json(&dir, "manifest.json");
    assert_eq!(m["status"], "complete");
    assert_eq!(
        m["plan_hash"], before["plan_hash"],
        "the plan's hash is kept"
    );
    assert_eq!(m["dut"]["serial"], "FIXTURE-S1");
    let resumes = m["resumes"].as_array().unwrap();
    assert_eq!(resumes.len(), 1, "{m}");
    assert_eq!(resumes[0]["from_step"], 2);
    assert_eq!(resumes[0]["previous_status"], "failed");
    check_complete_data(&dir, 5, 20);
    kept_as_prefix("sweep-interrupted", &dir, "samples.csv");
    kept_converted("sweep-interrupted", &dir);

    verify_passes(&dir, &["samples.csv", "steps.csv", "fit.json"]);
    std::fs::remove_file(dir.join("report.html")).unwrap();
    let doc = report(&dir);
    assert!(doc["warnings"].as_array().unwrap().is_empty(), "{doc}");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains("Fixture sweep"),
        "the plan's name on the report"
    );
    assert!(
        html.contains("FIXTURE-S1"),
        "the gyro's serial on the report"
    );
}

#[test]
fn an_interrupted_drift_record_of_the_earlier_release_resumes_verifies_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = fixture_rundir("drift-interrupted", tmp.path());
    let before = json(&dir, "manifest.json");
    assert_eq!(before["status"], "failed");
    assert_eq!(before["plan"]["kind"], "drift");
    assert_eq!(before["steps_done"], serde_json::json!([0, 1, 2]));

    let out = resume_to_completion(&dir);
    assert!(
        // a drift record's steps are its segments, one word for them (issue 25 item 5)
        out.stderr.contains("3 of 8 segments done, 5 to go"),
        "{}",
        out.stderr
    );
    assert_eq!(out.doc["steps_recorded_this_session"], 5, "{}", out.doc);
    let m = json(&dir, "manifest.json");
    assert_eq!(m["status"], "complete");
    assert_eq!(
        m["plan_hash"], before["plan_hash"],
        "the plan's hash is kept"
    );
    let resumes = m["resumes"].as_array().unwrap();
    assert_eq!(resumes.len(), 1, "{m}");
    assert_eq!(resumes[0]["from_step"], 3);
    check_complete_data(&dir, 8, 200);
    kept_as_prefix("drift-interrupted", &dir, "samples.csv");
    kept_converted("drift-interrupted", &dir);
    // the record is analysed: the Allan deviation of the whole record, in °/h (a simulated K)
    let allan = json(&dir, "allan.json");
    assert_eq!(allan["unit"], "deg/h", "{allan}");
    assert_eq!(allan["earth_rate"]["axis"], "up", "{allan}");

    verify_passes(
        &dir,
        &["samples.csv", "steps.csv", "allan.json", "allan.html"],
    );
    std::fs::remove_file(dir.join("allan.html")).unwrap();
    let doc = report(&dir);
    assert_eq!(doc["kind"], "drift", "{doc}");
    assert!(doc["warnings"].as_array().unwrap().is_empty(), "{doc}");
    let html = std::fs::read_to_string(dir.join("allan.html")).unwrap();
    assert!(
        html.contains("Fixture drift record"),
        "the plan's name on the page"
    );
}

/// Every value of `refit` (what `gyrocal fit --json` computes now) is in `kept` (the run's
/// fit.json) at the same place; numbers agree to the run directory's 12 significant digits.
/// `kept` may hold more (the uncertainty budget and the acceptance verdict are attached from
/// the manifest's records). Returns how many numbers were compared.
fn same_fit(kept: &serde_json::Value, refit: &serde_json::Value, at: &str) -> usize {
    use serde_json::Value;
    match (kept, refit) {
        (Value::Object(k), Value::Object(r)) => r
            .iter()
            .map(|(key, rv)| {
                let kv = k
                    .get(key)
                    .unwrap_or_else(|| panic!("{at}.{key}: not in fit.json"));
                same_fit(kv, rv, &format!("{at}.{key}"))
            })
            .sum(),
        (Value::Array(k), Value::Array(r)) => {
            assert_eq!(k.len(), r.len(), "{at}: lengths");
            k.iter()
                .zip(r)
                .enumerate()
                .map(|(i, (kv, rv))| same_fit(kv, rv, &format!("{at}[{i}]")))
                .sum()
        }
        (Value::Number(k), Value::Number(r)) => {
            let (k, r) = (k.as_f64().unwrap(), r.as_f64().unwrap());
            assert!(
                (k - r).abs() <= 1e-10 * k.abs().max(r.abs()),
                "{at}: {k} in fit.json, {r} fitted again"
            );
            1
        }
        (k, r) => {
            assert_eq!(k, r, "{at}");
            0
        }
    }
}

#[test]
fn a_complete_sweep_of_the_earlier_release_verifies_reports_and_keeps_its_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = fixture_rundir("sweep-complete", tmp.path());
    let m = json(&dir, "manifest.json");
    assert_eq!(m["status"], "complete");

    verify_passes(&dir, &["samples.csv", "steps.csv", "fit.json"]);
    // a complete run is not resumed again: refused as bad input, nothing written
    let samples_before = std::fs::read(dir.join("samples.csv")).unwrap();
    let out = run_json(&[&"--simulate", &"--resume", &dir]);
    assert_eq!(out.code, Some(2), "{}", out.stderr);
    assert!(out.stderr.contains("already complete"), "{}", out.stderr);
    assert_eq!(
        std::fs::read(dir.join("samples.csv")).unwrap(),
        samples_before
    );
    assert!(
        json(&dir, "manifest.json")["resumes"]
            .as_array()
            .unwrap()
            .is_empty()
    );

    std::fs::remove_file(dir.join("report.html")).unwrap();
    let doc = report(&dir);
    assert!(doc["warnings"].as_array().unwrap().is_empty(), "{doc}");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains("FIXTURE-S2"),
        "the gyro's serial on the report"
    );

    // the kept fit is the fit of the kept steps, as gyrocal fits them today
    let o = gyrocal()
        .args(["fit", "--json"])
        .arg(dir.join("steps.csv"))
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let mut refit =
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()["files"][0].take();
    // the file the fit read is named as given: not the same path as when the run wrote it
    refit.as_object_mut().unwrap().remove("source");
    let kept = json(&dir, "fit.json");
    let compared = same_fit(&kept, &refit, "fit.json");
    assert!(compared > 100, "only {compared} numbers compared");
    assert_eq!(kept["best_model"], m["fit_summary"]["best_model"]);
}
