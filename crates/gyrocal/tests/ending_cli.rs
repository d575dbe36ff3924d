//! One ending for every kind of run: the exit code and the last lines follow the table's rest
//! state the same way for a sweep and a drift record, and a run without a table says nothing was
//! moved. Against the simulated bench in virtual time (`gyrocal run --simulate`), with a table
//! that ignores the stop it is sent (`table:silent@stop1`: a controller that hangs when asked to
//! stop) after every step was recorded.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};

use common::{RunOutput, config, run_json};

const NOT_AT_REST: &str =
    "all steps recorded, but the table could NOT be confirmed at rest: stop it by hand";

/// configs/drift.toml, two segments of 100 readings.
fn short_drift(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(config("drift.toml"))
        .unwrap()
        .replace("samples_per_rate = 3000", "samples_per_rate = 100")
        .replace("repeat = 167", "repeat = 2");
    let path = dir.join("drift.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn assert_complete_but_not_at_rest(o: &RunOutput, what: &str) {
    assert_eq!(o.code, Some(1), "{what}: {}", o.stderr);
    assert_eq!(o.doc["status"], "complete", "{what}: {}", o.doc);
    assert_eq!(
        o.doc["table"]["at_rest"], false,
        "{what}: {}",
        o.doc["table"]
    );
    let last = o.stderr.lines().last().unwrap_or_default();
    assert!(last.contains(NOT_AT_REST), "{what}: last line {last:?}");
}

#[test]
fn a_complete_drift_record_whose_table_ignores_the_stop_exits_1_saying_stop_it_by_hand() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_drift(tmp.path());
    let out = tmp.path().join("run");
    let o = run_json(&[
        &plan,
        &"--simulate",
        &"--sim-fault",
        &"table:silent@stop1",
        &"--out",
        &out,
    ]);
    assert_complete_but_not_at_rest(&o, "drift");
    // the record itself is complete and analysed
    assert!(out.join("allan.json").is_file(), "{}", o.stderr);
}

#[test]
fn a_complete_sweep_whose_table_ignores_the_stop_ends_the_same_way() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let o = run_json(&[
        &config("quick.toml"),
        &"--simulate",
        &"--no-report",
        &"--sim-fault",
        &"table:silent@stop1",
        &"--out",
        &out,
    ]);
    assert_complete_but_not_at_rest(&o, "sweep");
}

#[test]
fn the_same_runs_with_a_table_that_obeys_exit_0_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_drift(tmp.path());
    for (what, plan) in [("drift", plan), ("sweep", config("quick.toml"))] {
        let out = tmp.path().join(format!("run-{what}"));
        let o = run_json(&[&plan, &"--simulate", &"--no-report", &"--out", &out]);
        assert_eq!(o.code, Some(0), "{what}: {}", o.stderr);
        assert_eq!(
            o.doc["table"]["at_rest"], true,
            "{what}: {}",
            o.doc["table"]
        );
        assert!(!o.stderr.contains("could NOT"), "{what}: {}", o.stderr);
    }
}
