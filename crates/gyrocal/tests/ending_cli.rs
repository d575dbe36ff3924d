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

/// configs/quick.toml with acceptance limits on the scale factor from `min` to `max` V/(°/s)
/// (the simulated gyro's K is 0.3612).
fn quick_with_limits(dir: &Path, name: &str, min: f64, max: f64) -> PathBuf {
    let text = std::fs::read_to_string(config("quick.toml")).unwrap()
        + &format!(
            "\n[acceptance]\ndecision_rule = \"simple\"\n[acceptance.scale_factor]\nmin = {min}\nmax = {max}\n"
        );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The line of `o`'s human text (stderr with `--json`) that starts with `prefix`.
fn line<'a>(o: &'a RunOutput, prefix: &str) -> &'a str {
    o.stderr
        .lines()
        .find(|l| l.starts_with(prefix))
        .unwrap_or_else(|| panic!("no line {prefix:?} in {}", o.stderr))
}

/// A complete run ends with its result in one line (K ± U at k = 2 and the verdict) and where
/// to look next; `--fail-on-verdict` turns a rejected gyro into exit 3 for CI, and a run
/// without a verdict too, while the run itself (its files, its JSON) is the same.
#[test]
fn the_result_in_one_line_and_the_verdict_as_an_exit_code_when_asked() {
    let tmp = tempfile::tempdir().unwrap();
    let good = quick_with_limits(tmp.path(), "good", 0.35, 0.37);
    let bad = quick_with_limits(tmp.path(), "bad", 0.30, 0.32);

    let o = run_json(&[
        &good,
        &"--simulate",
        &"--fail-on-verdict",
        &"--out",
        &tmp.path().join("g"),
    ]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let result = line(&o, "result: ");
    assert!(result.contains("K = 0.361"), "{result}");
    assert!(
        result.contains(" ± ") && result.contains("(k = 2)"),
        "{result}"
    );
    assert!(result.contains("verdict PASS (simple rule)"), "{result}");
    let next = o.stderr.lines().last().unwrap();
    assert!(
        next.starts_with("next: open ") && next.ends_with("report.html"),
        "{next}"
    );

    // the same rejected gyro: exit 0 unless asked, 3 when asked
    let plain = run_json(&[
        &bad,
        &"--simulate",
        &"--no-report",
        &"--out",
        &tmp.path().join("b0"),
    ]);
    assert_eq!(plain.code, Some(0), "{}", plain.stderr);
    assert!(line(&plain, "result: ").contains("verdict FAIL (simple rule)"));
    let asked = run_json(&[
        &bad,
        &"--simulate",
        &"--no-report",
        &"--fail-on-verdict",
        &"--out",
        &tmp.path().join("b1"),
    ]);
    assert_eq!(asked.code, Some(3), "{}", asked.stderr);
    assert_eq!(asked.doc["status"], "complete");
    assert_eq!(asked.doc["exit_code"], 3);
    assert!(asked.stderr.contains("verdict: FAIL"), "{}", asked.stderr);
    // a marginal level is stricter than fail, never laxer
    let pass_marginal = run_json(&[
        &good,
        &"--simulate",
        &"--no-report",
        &"--fail-on-verdict=marginal",
        &"--out",
        &tmp.path().join("g1"),
    ]);
    assert_eq!(pass_marginal.code, Some(0), "{}", pass_marginal.stderr);

    // no limits, no verdict: asked to fail on one, the run says so and exits 3
    let none = run_json(&[
        &config("quick.toml"),
        &"--simulate",
        &"--no-report",
        &"--fail-on-verdict",
        &"--out",
        &tmp.path().join("n"),
    ]);
    assert_eq!(none.code, Some(3), "{}", none.stderr);
    assert!(none.stderr.contains("has no verdict"), "{}", none.stderr);
    assert!(line(&none, "result: ").contains("no acceptance limits"));
}

/// A complete drift record ends with its noise terms in one line, in °/h.
#[test]
fn a_drift_record_ends_with_its_noise_terms() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = short_drift(tmp.path());
    let o = run_json(&[&plan, &"--simulate", &"--out", &tmp.path().join("d")]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    let result = line(&o, "result: ");
    assert!(
        result.contains("N = ") && result.contains("°/√h"),
        "{result}"
    );
    assert!(result.contains("(k = 2)"), "{result}");
    assert!(
        o.doc["page"].as_str().unwrap().ends_with("allan.html"),
        "{}",
        o.doc
    );
}

/// The common-K2 asymmetry of a 5-step sweep has 1 degree of freedom: the terminal and the
/// certificate say so beside the figure (as `gyrocal check` warned); the paper's 19 steps
/// leave 15 and nothing is said.
#[test]
fn too_few_degrees_of_freedom_are_said_beside_the_asymmetry() {
    let tmp = tempfile::tempdir().unwrap();
    const FEW: &str = "only 1 degree of freedom: too few residuals";
    let quick = tmp.path().join("quick");
    let o = run_json(&[&config("quick.toml"), &"--simulate", &"--out", &quick]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    assert!(
        line(&o, "  asymmetry, common K2").contains(FEW),
        "{}",
        o.stderr
    );
    let html = std::fs::read_to_string(quick.join("report.html")).unwrap();
    assert!(
        html.contains(FEW),
        "the certificate says it beside the figure"
    );

    let paper = tmp.path().join("paper");
    let o = run_json(&[&config("paper.toml"), &"--simulate", &"--out", &paper]);
    assert_eq!(o.code, Some(0), "{}", o.stderr);
    assert!(
        !line(&o, "  asymmetry, common K2").contains("degree"),
        "{}",
        o.stderr
    );
    let html = std::fs::read_to_string(paper.join("report.html")).unwrap();
    assert!(!html.contains("degree of freedom: too few"));
}

/// A refused verdict never hides a table that could not be confirmed at rest: asked to fail
/// on the verdict, a rejected gyro on a table that ignores the stop still exits 1 (not 3)
/// with "stop it by hand" as the last line.
#[test]
fn a_refused_verdict_with_a_table_that_ignores_the_stop_exits_1_saying_stop_it_by_hand() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = quick_with_limits(tmp.path(), "bad", 0.30, 0.32);
    let o = run_json(&[
        &bad,
        &"--simulate",
        &"--no-report",
        &"--fail-on-verdict",
        &"--sim-fault",
        &"table:silent@stop1",
        &"--out",
        &tmp.path().join("run"),
    ]);
    assert_complete_but_not_at_rest(&o, "sweep with a refused verdict");
    assert!(
        line(&o, "result: ").contains("verdict FAIL"),
        "{}",
        o.stderr
    );
}
