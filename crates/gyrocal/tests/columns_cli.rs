//! The run directory's counted columns (issue 25, item 9), through the binary: a fresh run
//! writes `step_no`, `sample_no` and `pass_no`, counted from 1 like the terminal ("step 1/5"
//! is `step_no` 1) and `gyrocal check --json`; a run an older gyrocal began (columns `step`,
//! `index`, `pass`, counted from 0) resumed by this one keeps appending samples.csv rows in the
//! file's own format, gets steps.csv rewritten in the new one, and still verifies and fits
//! the same.
//!
//! Run: `cargo nextest run -p gyrocal -E 'binary(columns_cli)'`.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::{config, final_table_state, fixture_rundir, gyrocal, json, run_json};

/// A CSV file as (header, rows of cells).
fn table(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h = r.headers().unwrap().iter().map(String::from).collect();
    let rows = r
        .records()
        .map(|rec| rec.unwrap().iter().map(String::from).collect())
        .collect();
    (h, rows)
}

/// The cells of column `name` as numbers (`u64`).
fn column(h: &[String], rows: &[Vec<String>], name: &str) -> Vec<u64> {
    let i = h
        .iter()
        .position(|c| c == name)
        .unwrap_or_else(|| panic!("no column {name} in {h:?}"));
    rows.iter().map(|r| r[i].parse().unwrap()).collect()
}

/// The cells of column `name` as `f64`.
fn column_f64(h: &[String], rows: &[Vec<String>], name: &str) -> Vec<f64> {
    let i = h.iter().position(|c| c == name).unwrap();
    rows.iter().map(|r| r[i].parse().unwrap()).collect()
}

#[test]
fn a_fresh_run_counts_from_one_in_columns_that_say_so_as_the_terminal_does() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = config("quick.toml");
    let out = run_json(&[&plan, &"--simulate", &"--out", &dir]);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    assert_eq!(final_table_state(&out.stderr)["stopped"], true);

    // the headers a pandas user reads: no `index`, no `pass`, no bare `step`
    let (sh, srows) = table(&dir.join("samples.csv"));
    assert_eq!(
        sh,
        [
            "step_no",
            "sample_no",
            "t_s",
            "rate_dps",
            "volts",
            "overload",
            "t_utc"
        ]
    );
    let (th, trows) = table(&dir.join("steps.csv"));
    assert_eq!(th[..3], ["step_no", "pass_no", "rate_dps"]);
    for old in ["step", "index", "pass"] {
        assert!(
            !sh.iter().chain(&th).any(|c| c == old),
            "{old} in {sh:?} {th:?}"
        );
    }

    // steps.csv: step_no 1..=5, pass_no 1 (quick.toml runs its rates once)
    assert_eq!(column(&th, &trows, "step_no"), [1, 2, 3, 4, 5]);
    assert_eq!(column(&th, &trows, "pass_no"), [1; 5]);
    let rates = column_f64(&th, &trows, "rate_dps");
    assert_eq!(rates, [0.0, 1.0, -1.0, 10.0, -10.0]);

    // samples.csv: the first reading of the first step is step_no 1, sample_no 1; each step's
    // readings are numbered 1..=50 and carry that step's rate
    assert_eq!(srows[0][..2], ["1", "1"]);
    let steps = column(&sh, &srows, "step_no");
    let nos = column(&sh, &srows, "sample_no");
    let srates = column_f64(&sh, &srows, "rate_dps");
    let mut per_step: BTreeMap<u64, Vec<u64>> = BTreeMap::new();
    for ((s, n), r) in steps.iter().zip(&nos).zip(&srates) {
        assert_eq!(*r, rates[*s as usize - 1], "step_no {s} sample_no {n}");
        per_step.entry(*s).or_default().push(*n);
    }
    assert_eq!(
        per_step.keys().copied().collect::<Vec<_>>(),
        [1, 2, 3, 4, 5]
    );
    for (s, n) in &per_step {
        assert_eq!(*n, (1..=50).collect::<Vec<_>>(), "step_no {s}");
    }

    // the terminal's "step N/5 RATE" is the files' step_no N at that rate
    for (n, rate) in (1..).zip(&rates) {
        let prefix = format!("step {n}/5 ");
        let line = out
            .stderr
            .lines()
            .find_map(|l| l.trim_start().strip_prefix(prefix.as_str()))
            .unwrap_or_else(|| panic!("no {prefix:?} on the terminal:\n{}", out.stderr));
        let said: f64 = line.split_whitespace().next().unwrap().parse().unwrap();
        assert_eq!(said, *rate, "step {n}: {line}");
    }

    // `gyrocal check --json` numbers the steps the same way
    let o = gyrocal()
        .arg("check")
        .arg(&plan)
        .arg("--json")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let check: Vec<(u64, u64, f64)> = doc["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["step_no"].as_u64().unwrap(),
                s["pass_no"].as_u64().unwrap(),
                s["rate_dps"].as_f64().unwrap(),
            )
        })
        .collect();
    let files: Vec<(u64, u64, f64)> = column(&th, &trows, "step_no")
        .into_iter()
        .zip(column(&th, &trows, "pass_no"))
        .zip(rates)
        .map(|((s, p), r)| (s, p, r))
        .collect();
    assert_eq!(check, files);
    // and its table's headers say what they count
    let o = gyrocal().arg("check").arg(&plan).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.lines()
            .any(|l| l.split_whitespace().take(2).eq(["step_no", "pass_no"])),
        "{text}"
    );
}

/// Every number of `refit` is in `kept` at the same place, equal to 12 significant digits (the
/// run directory rounds to 12). Returns how many numbers were compared.
fn same_numbers(kept: &serde_json::Value, refit: &serde_json::Value, at: &str) -> usize {
    use serde_json::Value;
    match (kept, refit) {
        (Value::Object(k), Value::Object(r)) => r
            .iter()
            .map(|(key, rv)| {
                let kv = k
                    .get(key)
                    .unwrap_or_else(|| panic!("{at}.{key}: not in fit.json"));
                same_numbers(kv, rv, &format!("{at}.{key}"))
            })
            .sum(),
        (Value::Array(k), Value::Array(r)) => {
            assert_eq!(k.len(), r.len(), "{at}: lengths");
            k.iter()
                .zip(r)
                .enumerate()
                .map(|(i, (kv, rv))| same_numbers(kv, rv, &format!("{at}[{i}]")))
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
fn a_run_of_the_old_format_resumed_appends_in_its_own_format_and_verifies_and_fits_the_same() {
    let tmp = tempfile::tempdir().unwrap();
    // the earlier release's interrupted sweep: steps 1 and 2 of 5 kept, counted from 0
    let dir = fixture_rundir("sweep-interrupted", tmp.path());
    let samples_before = std::fs::read_to_string(dir.join("samples.csv")).unwrap();
    assert!(samples_before.starts_with("step,index,t_s,"));
    // the readings of an unfinished third step (`step` 2 in that format), which the resume
    // must recognise as such, drop, and take again
    let mut with_partial = samples_before.clone();
    for i in 0..3 {
        with_partial += &format!("2,{i},9.{i},-1.0,-0.36,0,2026-11-27T02:18:21.000Z\n");
    }
    std::fs::write(dir.join("samples.csv"), &with_partial).unwrap();

    let out = run_json(&[&"--simulate", &"--resume", &dir]);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    assert_eq!(out.doc["status"], "complete", "{}", out.doc);
    let end = final_table_state(&out.stderr);
    assert_eq!(end["stopped"], true, "{end}");
    let m = json(&dir, "manifest.json");
    assert_eq!(m["resumes"][0]["samples_dropped"], 3, "{}", m["resumes"]);
    assert_eq!(m["format_version"], 3);

    // samples.csv: the old rows byte for byte, then the new session's rows in the file's own
    // columns, counted from 0: steps 2, 3, 4 with index 0..20 each
    let after = std::fs::read_to_string(dir.join("samples.csv")).unwrap();
    assert!(
        after.starts_with(&samples_before),
        "the kept rows are not kept"
    );
    let (sh, srows) = table(&dir.join("samples.csv"));
    assert_eq!(sh[..2], ["step", "index"]);
    let steps = column(&sh, &srows, "step");
    let index = column(&sh, &srows, "index");
    let want: Vec<(u64, u64)> = (0..5).flat_map(|s| (0..20).map(move |i| (s, i))).collect();
    let got: Vec<(u64, u64)> = steps.into_iter().zip(index).collect();
    assert_eq!(got, want, "every reading once, in the file's own numbering");

    // steps.csv: rewritten in the new columns, counted from 1
    let (th, trows) = table(&dir.join("steps.csv"));
    assert_eq!(th[..2], ["step_no", "pass_no"]);
    assert_eq!(column(&th, &trows, "step_no"), [1, 2, 3, 4, 5]);
    assert_eq!(column(&th, &trows, "pass_no"), [1; 5]);

    // and the run verifies, reports, and fits the same from its directory as it fitted itself
    let o = gyrocal().arg("verify").arg(&dir).output().unwrap();
    let said = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{said}");
    for f in ["samples.csv ok", "steps.csv ok", "fit.json ok"] {
        assert!(said.contains(f), "{f} in {said}");
    }
    let o = gyrocal()
        .args(["report", "--json"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = gyrocal()
        .args(["fit", "--json"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // `fit --json` prints {"files": [ANALYSIS, ...], ...}: one file's analysis is files[0]
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let mut refit = doc["files"][0].clone();
    refit.as_object_mut().unwrap().remove("source");
    let compared = same_numbers(&json(&dir, "fit.json"), &refit, "fit.json");
    assert!(compared > 100, "only {compared} numbers compared");
}

#[test]
fn a_complete_run_of_the_old_format_reads_as_before() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = fixture_rundir("sweep-complete", tmp.path());
    // the report reads its steps through gyrocal-files: counted from 0 in this file, the five
    // steps are the plan's five
    let o = gyrocal()
        .args(["report", "--json"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = gyrocal().arg("verify").arg(&dir).output().unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    // the Allan analysis of its samples (by `t_s` and `volts`, whatever the counted columns)
    let o = gyrocal()
        .args(["allan", "--json"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(doc.is_object(), "{doc}");
}
