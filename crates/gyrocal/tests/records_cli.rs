//! Calibration records as a lab reads them (issue 13's "done when"): a simulated run of the
//! paper's plan naming the gyro, with a station file and acceptance limits, gives a report
//! whose first page names the serial and the verdict, whose tables agree with fit.json; the
//! guarded decision rule says "indeterminate" within the uncertainty of a limit; an overdue
//! instrument refuses a run unless --allow-expired, which is recorded as a deviation.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::Path;

use common::{between, config, gyrocal, json};

/// The station file: bench 2, with the room's conditions (22.5 °C, 41 %).
fn station_toml() -> String {
    common::stations::bench_2(common::stations::CONDITIONS)
}

/// configs/paper.toml with a `[dut]` and the given `[acceptance]` section.
fn paper_plan(dir: &Path, acceptance: &str) -> std::path::PathBuf {
    let mut text = std::fs::read_to_string(config("paper.toml")).unwrap();
    text.push_str(
        "\n[dut]\nserial = \"HRG-0421\"\nmodel = \"HRG-30\"\nmanufacturer = \"Example Gyro Works\"\ncondition = \"as received, no visible damage\"\n\n",
    );
    text.push_str(acceptance);
    let path = dir.join("paper-dut.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn station(dir: &Path, text: &str) -> std::path::PathBuf {
    let path = dir.join("station.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// The first number in `text` (after stripping tags).
fn number_in(cell: &str) -> f64 {
    let mut plain = String::new();
    let mut in_tag = false;
    for c in cell.chars() {
        match c {
            '<' => in_tag = true,
            '>' => in_tag = false,
            _ if !in_tag => plain.push(c),
            _ => {}
        }
    }
    let plain = plain.replace('−', "-").replace('\u{2009}', "");
    let start = plain
        .find(|c: char| c.is_ascii_digit() || c == '-' || c == '+')
        .unwrap_or_else(|| panic!("no number in {cell:?}"));
    let tail = &plain[start..];
    let end = tail
        .find(|c: char| !(c.is_ascii_digit() || "+-.eE".contains(c)))
        .unwrap_or(tail.len());
    tail[..end]
        .parse()
        .unwrap_or_else(|e| panic!("{:?} in {cell:?}: {e}", &tail[..end]))
}

/// The contents of the element with `id` in `html`.
fn cell<'a>(html: &'a str, id: &str) -> &'a str {
    let from = format!("id=\"{id}\"");
    let i = html
        .find(&from)
        .unwrap_or_else(|| panic!("no element with id {id}"));
    let rest = &html[i + from.len()..];
    let open = rest.find('>').unwrap() + 1;
    let close = rest[open..].find("</t").unwrap();
    &rest[open..open + close]
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs())
}

#[test]
fn a_failing_quantity_is_named_on_the_first_page_with_the_serial_and_the_tables_match_fit_json() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = paper_plan(
        tmp.path(),
        "[acceptance]\ndecision_rule = \"simple\"\n\n[acceptance.scale_factor]\nmin = 0.35\nmax = 0.37\n\n[acceptance.bias_dph]\nmin = -500\nmax = 500\n\n[acceptance.nonlinearity_ppm]\nmax = 500\n",
    );
    let station = station(tmp.path(), &station_toml());
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(&plan)
        .args([
            "--simulate",
            "--json",
            "--operator",
            "A. Tester",
            "--station",
        ])
        .arg(&station)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let fit = json(&out, "fit.json");
    let manifest = json(&out, "manifest.json");

    // one verdict, the same in --json, fit.json and the manifest
    assert_eq!(
        fit["acceptance"]["verdict"], "fail",
        "{:#}",
        fit["acceptance"]
    );
    assert_eq!(doc["acceptance"], fit["acceptance"]);
    assert_eq!(manifest["acceptance"], fit["acceptance"]);
    let checks = fit["acceptance"]["checks"].as_array().unwrap();
    let verdict_of = |q: &str| {
        checks
            .iter()
            .find(|c| c["quantity"] == q)
            .unwrap_or_else(|| panic!("no check of {q}"))["verdict"]
            .clone()
    };
    assert_eq!(verdict_of("nonlinearity_ppm"), "fail");
    assert_eq!(verdict_of("scale_factor"), "pass");
    assert_eq!(verdict_of("bias_dph"), "pass");
    // the station and the gyro are recorded
    assert_eq!(manifest["station"]["multimeter"]["asset_id"], "DMM-0042");
    assert_eq!(manifest["dut"]["serial"], "HRG-0421");

    // the first printed page: everything before the test conditions
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let first_page = &html[..html
        .find("id=\"conditions\"")
        .expect("a conditions section")];
    assert!(first_page.contains("HRG-0421"), "serial on page 1");
    let verdict = between(first_page, "id=\"acceptance-verdict\"", "</div>");
    assert!(verdict.contains("FAIL"), "verdict box: {verdict}");
    assert!(
        verdict.contains("nonlinearity"),
        "the failing quantity is named: {verdict}"
    );
    assert!(
        !verdict.contains("scale factor") && !verdict.contains("scale_factor"),
        "only failing quantities are named in the verdict: {verdict}"
    );
    assert!(first_page.contains("Inertial Lab, Example Institute"));

    // the results table agrees with fit.json (value and U, k = 2)
    for q in fit["uncertainty"]["quantities"].as_array().unwrap() {
        let name = q["quantity"].as_str().unwrap();
        let value = q["value"].as_f64().unwrap();
        let u = q["expanded_uncertainty"].as_f64().unwrap();
        let shown = number_in(cell(&html, &format!("res-{name}")));
        let shown_u = number_in(cell(&html, &format!("res-{name}-u")));
        // U to two significant digits (within 5 %), the value to a digit beyond U's last
        assert!(
            close(shown_u, u, 0.05),
            "{name}: U shown {shown_u}, fit.json {u}"
        );
        assert!(
            (shown - value).abs() <= 0.006 * u,
            "{name}: shown {shown}, fit.json {value} ± {u}"
        );
    }
    // the acceptance table agrees with fit.json
    for c in checks {
        let q = c["quantity"].as_str().unwrap();
        let shown = cell(&html, &format!("acc-{q}-verdict"));
        assert!(
            shown
                .to_lowercase()
                .contains(c["verdict"].as_str().unwrap()),
            "{q}: shown {shown}, fit.json {}",
            c["verdict"]
        );
    }
    // the budget names the meter's and the table's accuracy from the station file
    let budget = between(&html, "id=\"uncertainty\"", "id=\"fit\"");
    assert!(
        budget.contains("DMM-0042") || budget.contains("34401A"),
        "{budget}"
    );
    assert!(
        budget.contains("10 ppm") || budget.contains("TBL-0007"),
        "{budget}"
    );
    // the instruments with their calibration records
    let instruments = between(&html, "id=\"instruments\"", "</table>");
    for s in [
        "DMM-0042",
        "3146A12345",
        "CAL-2026-0815",
        "2099-08-15",
        "TBL-0007",
    ] {
        assert!(instruments.contains(s), "{s} not in {instruments}");
    }
}

#[test]
fn the_guarded_rule_is_indeterminate_within_the_uncertainty_of_a_limit() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = paper_plan(tmp.path(), "");
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(&plan)
        .args(["--simulate", "--no-report", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let fit = json(&out, "fit.json");
    let k = fit["uncertainty"]["quantities"]
        .as_array()
        .unwrap()
        .iter()
        .find(|q| q["quantity"] == "scale_factor")
        .unwrap()
        .clone();
    let value = k["value"].as_f64().unwrap();
    let u = k["expanded_uncertainty"].as_f64().unwrap();
    assert!(u > 0.0);
    // a limit half an uncertainty above the value: inside the limit, but not by U
    let limits = tmp.path().join("limits.toml");
    std::fs::write(
        &limits,
        format!(
            "decision_rule = \"guarded\"\n[scale_factor]\nmin = {}\nmax = {}\n",
            value - 10.0 * u,
            value + 0.5 * u
        ),
    )
    .unwrap();
    let html_path = tmp.path().join("guarded.html");
    let o = gyrocal()
        .arg("report")
        .arg(&out)
        .arg("--acceptance")
        .arg(&limits)
        .arg("-o")
        .arg(&html_path)
        .arg("--json")
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["acceptance"]["verdict"], "indeterminate", "{doc:#}");
    let html = std::fs::read_to_string(&html_path).unwrap();
    let verdict = between(&html, "id=\"acceptance-verdict\"", "</div>");
    assert!(verdict.contains("INDETERMINATE"), "{verdict}");
    assert!(verdict.contains("guarded"), "the rule is stated: {verdict}");
    // the same limits under the simple rule: the value is inside, so it passes
    std::fs::write(
        &limits,
        format!(
            "decision_rule = \"simple\"\n[scale_factor]\nmin = {}\nmax = {}\n",
            value - 10.0 * u,
            value + 0.5 * u
        ),
    )
    .unwrap();
    let o = gyrocal()
        .arg("report")
        .arg(&out)
        .arg("--acceptance")
        .arg(&limits)
        .arg("-o")
        .arg(&html_path)
        .arg("--json")
        .output()
        .unwrap();
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["acceptance"]["verdict"], "pass", "{doc:#}");
    // the run's own fit.json is not rewritten by a re-evaluation
    assert_eq!(json(&out, "fit.json"), fit);
}

#[test]
fn an_overdue_calibration_refuses_the_run_unless_allowed_and_then_is_a_deviation() {
    let tmp = tempfile::tempdir().unwrap();
    let expired = station_toml()
        .replace("calibrated = \"2026-08-15\"", "calibrated = \"2019-01-31\"")
        .replace("due = \"2099-08-15\"", "due = \"2020-01-31\"");
    let station = station(tmp.path(), &expired);
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--station"])
        .arg(&station)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("DMM-0042") && stderr.contains("2020-01-31"),
        "{stderr}"
    );
    assert!(stderr.contains("--allow-expired"), "{stderr}");
    assert!(!out.exists(), "nothing is created when the run is refused");

    // the same through the environment variable, allowed: recorded as a deviation
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--allow-expired", "--out"])
        .arg(&out)
        .env("GYROCAL_STATION", &station)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    let manifest = json(&out, "manifest.json");
    let devs = manifest["deviations"].as_array().expect("deviations");
    assert!(
        devs.iter().any(|d| d["kind"] == "expired-calibration"
            && d["text"].as_str().unwrap().contains("DMM-0042")),
        "{devs:?}"
    );
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let list = between(&html, "id=\"deviations-list\"", "</ul>");
    assert!(
        list.contains("DMM-0042") && list.contains("allow-expired"),
        "{list}"
    );
}

#[test]
fn a_station_file_that_is_missing_or_malformed_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nowhere.toml");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--station"])
        .arg(&missing)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("nowhere.toml"), "{stderr}");
    let bad = station(
        tmp.path(),
        "id = \"b\"\n[multimeter]\nasset_id = \"X\"\ndue = \"not a date\"\n",
    );
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--station"])
        .arg(&bad)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("station.toml") && stderr.contains("due"),
        "{stderr}"
    );
}

#[test]
fn a_simulated_certificate_names_the_simulated_instruments_and_gyro() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let manifest = json(&out, "manifest.json");
    let serial = manifest["dut"]["serial"]
        .as_str()
        .expect("a simulated serial");
    assert!(serial.starts_with("SIM-"), "{serial}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let first_page = &html[..html.find("id=\"conditions\"").unwrap()];
    assert!(first_page.contains(serial));
    assert!(first_page.contains("SIMULATED"));
    let instruments = between(&html, "id=\"instruments\"", "</table>");
    assert!(instruments.contains("SIM-"), "{instruments}");
    assert!(!html.contains("instruments-not-identified"));
}

/// configs/quick.toml interrupted by a meter that disconnects, with the station given.
fn interrupted_quick_run(dir: &Path, station_file: &Path) -> std::path::PathBuf {
    let out = dir.join("run");
    let o = gyrocal()
        .args([
            "run",
            "--simulate",
            "--sim-fault",
            "dmm:disconnect@reading120",
        ])
        .arg("--station")
        .arg(station_file)
        .arg("--out")
        .arg(&out)
        .arg(config("quick.toml"))
        .output()
        .unwrap();
    assert_ne!(o.status.code(), Some(0), "the fault interrupts the run");
    out
}

fn station_deviations(out: &Path) -> Vec<String> {
    json(out, "manifest.json")["deviations"]
        .as_array()
        .map(|d| {
            d.iter()
                .filter(|x| x["kind"] == "station-changed")
                .map(|x| x["text"].as_str().unwrap().to_string())
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_resume_on_another_station_is_a_deviation_and_on_the_same_one_is_not() {
    let tmp = tempfile::tempdir().unwrap();
    let a = station(tmp.path(), &station_toml());
    // the same station: nothing to record
    let out = interrupted_quick_run(tmp.path(), &a);
    let o = gyrocal()
        .args(["run", "--simulate", "--station"])
        .arg(&a)
        .arg("--resume")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(station_deviations(&out).is_empty());

    // another multimeter: the certificate must say the run was finished on it
    let tmp = tempfile::tempdir().unwrap();
    let a = station(tmp.path(), &station_toml());
    let out = interrupted_quick_run(tmp.path(), &a);
    let b = tmp.path().join("other-station.toml");
    std::fs::write(
        &b,
        station_toml()
            .replace("DMM-0042", "DMM-0099")
            .replace("3146A12345", "3146A99999"),
    )
    .unwrap();
    let o = gyrocal()
        .args(["run", "--simulate", "--station"])
        .arg(&b)
        .arg("--resume")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains("resumed on station bench-2 with multimeter DMM-0099"),
        "{stderr}"
    );
    let d = station_deviations(&out);
    assert_eq!(d.len(), 1, "{d:?}");
    assert!(
        d[0].contains("DMM-0042") && d[0].contains("DMM-0099"),
        "{}",
        d[0]
    );
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        report.contains("DMM-0099"),
        "the report lists the deviation"
    );
}
