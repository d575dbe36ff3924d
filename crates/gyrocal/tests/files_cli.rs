//! The run directory's files and the report as a lab sees them after `gyrocal run` and
//! `gyrocal report`: UTC times, clean numbers, a slim manifest, no leftover lock, reports
//! written where the run is, runs of different plans called so, simulated runs marked; and run
//! directories of the previous format still report and resume.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::Path;
use std::process::Output;

use common::{config, gyrocal, manifest};

fn text(out: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// `gyrocal run PLAN --simulate --out DIR` plus `extra`; the output.
fn simulate(plan: &Path, dir: &Path, extra: &[&str]) -> Output {
    gyrocal()
        .arg("run")
        .arg(plan)
        .args(["--simulate", "--out"])
        .arg(dir)
        .args(extra)
        .output()
        .unwrap()
}

/// Every number token of a CSV or JSON text that has a decimal point.
fn numbers(text: &str) -> Vec<&str> {
    text.split(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '-' | 'e' | 'E' | '+')))
        .filter(|t| {
            t.contains('.')
                && t.chars()
                    .next()
                    .is_some_and(|c| c.is_ascii_digit() || c == '-')
        })
        .collect()
}

fn significant(token: &str) -> usize {
    let mantissa = token.split(['e', 'E']).next().unwrap_or(token);
    let digits: String = mantissa.chars().filter(char::is_ascii_digit).collect();
    digits.trim_start_matches('0').trim_end_matches('0').len()
}

fn header(path: &Path) -> Vec<String> {
    let mut r = csv::Reader::from_path(path).unwrap();
    r.headers().unwrap().iter().map(String::from).collect()
}

#[test]
fn a_simulated_run_writes_utc_times_clean_numbers_a_slim_manifest_and_no_lock() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let before = std::time::SystemTime::now();
    let out = simulate(&config("quick.toml"), &dir, &[]);
    assert!(out.status.success(), "{}", text(&out));

    // absolute UTC beside every relative time
    assert_eq!(header(&dir.join("samples.csv")).last().unwrap(), "t_utc");
    let h = header(&dir.join("steps.csv"));
    assert!(
        h.ends_with(&["t_start_utc".to_string(), "t_end_utc".to_string()]),
        "{h:?}"
    );
    let mut r = csv::Reader::from_path(dir.join("samples.csv")).unwrap();
    let rows: Vec<csv::StringRecord> = r.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 5 * 50);
    for row in &rows {
        let t = gyrocal_files::rundir::SAMPLES_HEADER.len() - 1;
        let utc = gyrocal_files::parse_rfc3339_utc(&row[t]).expect("an RFC 3339 time");
        assert!(utc >= before - std::time::Duration::from_secs(1), "{row:?}");
    }

    // no float noise in any data file
    for name in ["samples.csv", "steps.csv", "manifest.json", "fit.json"] {
        let body = std::fs::read_to_string(dir.join(name)).unwrap();
        let noisy: Vec<&str> = numbers(&body)
            .into_iter()
            .filter(|n| significant(n) > 12)
            .collect();
        assert!(noisy.is_empty(), "{name}: {noisy:?}");
    }

    // the manifest references fit.json instead of embedding it, and names its times
    let m = manifest(&dir);
    assert!(m.get("fit").is_none());
    let fit_bytes = std::fs::read(dir.join("fit.json")).unwrap();
    assert_eq!(
        m["fit_summary"]["sha256"].as_str().unwrap(),
        gyrocal_files::rundir::sha256_hex(&fit_bytes)
    );
    assert!(m["fit_summary"]["scale_factor"].as_f64().unwrap() > 0.3);
    let size = std::fs::metadata(dir.join("manifest.json")).unwrap().len();
    assert!(size < 8 * 1024, "manifest.json is {size} bytes");
    assert_eq!(m["plan"]["name"], "Quick check (5 rates, 50 readings)");
    assert!(m["plan"].get("plan").is_none());
    let whole = m["elapsed_s"].as_f64().unwrap();
    let schedule = m["timing"]["schedule_elapsed_s"].as_f64().unwrap();
    assert!(schedule > 0.0 && schedule <= whole, "{schedule} vs {whole}");
    assert_eq!(m["virtual_time"], true);

    // nothing left of the lock
    assert!(!dir.join(".lock").exists());

    // the report says SIMULATED before anything else, and explains the virtual clock
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    let banner = html.find("id=\"simulated\"").expect("a SIMULATED banner");
    assert!(banner < html.find("id=\"summary\"").unwrap());
    assert!(html.contains("<title>SIMULATED"), "title");
    assert!(html.contains("virtual time"), "no word on virtual time");
}

#[test]
fn report_writes_into_the_run_directory_not_the_current_one() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let out = simulate(&config("quick.toml"), &dir, &["--no-report"]);
    assert!(out.status.success(), "{}", text(&out));
    let cwd = tmp.path().join("elsewhere");
    std::fs::create_dir(&cwd).unwrap();
    let out = gyrocal()
        .current_dir(&cwd)
        .arg("report")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    assert!(dir.join("report.html").is_file() && dir.join("fit.svg").is_file());
    let litter: Vec<_> = std::fs::read_dir(&cwd).unwrap().collect();
    assert!(litter.is_empty(), "the current directory got {litter:?}");

    // -o is --out
    let other = tmp.path().join("out/cal.html");
    std::fs::create_dir_all(other.parent().unwrap()).unwrap();
    let out = gyrocal()
        .arg("report")
        .arg(&dir)
        .arg("-o")
        .arg(&other)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    assert!(other.is_file() && other.with_file_name("residuals.svg").is_file());
}

#[test]
fn runs_of_different_plans_are_not_called_repeatable() {
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    let c = tmp.path().join("c");
    let changed = tmp.path().join("changed.toml");
    std::fs::write(
        &changed,
        std::fs::read_to_string(config("quick.toml"))
            .unwrap()
            .replace("samples_per_rate = 50", "samples_per_rate = 40"),
    )
    .unwrap();
    for (dir, plan) in [
        (&a, config("quick.toml")),
        (&b, config("quick.toml")),
        (&c, changed),
    ] {
        let out = simulate(&plan, dir, &["--no-report"]);
        assert!(out.status.success(), "{}", text(&out));
    }

    // several inputs need -o: their report belongs to none of them
    let out = gyrocal().arg("report").arg(&a).arg(&b).output().unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(text(&out).contains("-o"), "{}", text(&out));

    // the same plan: a repeatability, no warning
    let same = tmp.path().join("same.html");
    let out = gyrocal()
        .arg("report")
        .args([&a, &b])
        .arg("-o")
        .arg(&same)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    assert!(!String::from_utf8_lossy(&out.stderr).contains("different plans"));
    let html = std::fs::read_to_string(&same).unwrap();
    assert!(html.contains("id=\"sum-repeatability\""));

    // different plans: a warning on stderr, the report says so, and gives no repeatability
    let mixed = tmp.path().join("mixed.html");
    let out = gyrocal()
        .arg("report")
        .args([&a, &c])
        .arg("-o")
        .arg(&mixed)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("warning") && err.contains("different plans"),
        "{err}"
    );
    let html = std::fs::read_to_string(&mixed).unwrap();
    assert!(html.contains("id=\"banner-plans\""));
    assert!(!html.contains("id=\"sum-repeatability\""));
    assert!(!html.contains("Repeatability over"));
}

/// Rewrites a run directory as gyrocal wrote it before this format (manifest format 1 with the
/// nested plan, `timing.elapsed_s`, the fit embedded, no fit summary; no UTC columns).
fn make_format_1(dir: &Path) {
    let path = dir.join("manifest.json");
    let mut m = manifest(dir);
    let obj = m.as_object_mut().unwrap();
    obj.insert("format_version".into(), 1.into());
    obj.remove("virtual_time");
    obj.remove("fit_summary");
    // format 1 recorded no checksums (and the CSVs are rewritten below)
    obj.remove("checksums");
    let mut plan = obj.remove("plan").unwrap();
    let p = plan.as_object_mut().unwrap();
    let mut nested = serde_json::json!({});
    for key in ["table", "dmm", "simulation"] {
        nested[key] = p.remove(key).unwrap();
    }
    nested["plan"] = serde_json::Value::Object(p.clone());
    obj.insert("plan".into(), nested);
    if let Some(t) = obj.get_mut("timing").and_then(|t| t.as_object_mut()) {
        let e = t.remove("schedule_elapsed_s").unwrap();
        t.insert("elapsed_s".into(), e);
    }
    if let Ok(fit) = std::fs::read_to_string(dir.join("fit.json")) {
        obj.insert("fit".into(), serde_json::from_str(&fit).unwrap());
        std::fs::remove_file(dir.join("fit.json")).unwrap();
    }
    std::fs::write(&path, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    for (name, k) in [("samples.csv", 1), ("steps.csv", 2)] {
        let body = std::fs::read_to_string(dir.join(name)).unwrap();
        let out: String = body
            .lines()
            .map(|l| {
                let cells: Vec<&str> = l.split(',').collect();
                format!("{}\n", cells[..cells.len() - k].join(","))
            })
            .collect();
        std::fs::write(dir.join(name), counted_from_zero(&out)).unwrap();
    }
}

/// A CSV of the current format with its counted columns as gyrocal wrote them before format
/// 3: `step_no`, `sample_no`, `pass_no` named `step`, `index`, `pass` and counted from 0.
fn counted_from_zero(text: &str) -> String {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let old = |h: &str| match h {
        "step_no" => Some("step"),
        "sample_no" => Some("index"),
        "pass_no" => Some("pass"),
        _ => None,
    };
    let renamed: Vec<&str> = header.iter().map(|h| old(h).unwrap_or(h)).collect();
    let mut out = renamed.join(",") + "\n";
    for l in lines {
        let cells: Vec<String> = l
            .split(',')
            .zip(&header)
            .map(|(c, h)| match old(h) {
                Some(_) => (c.parse::<u64>().unwrap() - 1).to_string(),
                None => c.to_string(),
            })
            .collect();
        out += &(cells.join(",") + "\n");
    }
    out
}

#[test]
fn run_directories_of_the_previous_format_still_report_and_resume() {
    let tmp = tempfile::tempdir().unwrap();
    // a complete old run with its fit in the manifest: the report reads it
    let done = tmp.path().join("done");
    let out = simulate(&config("quick.toml"), &done, &["--no-report"]);
    assert!(out.status.success(), "{}", text(&out));
    make_format_1(&done);
    let out = gyrocal().arg("report").arg(&done).output().unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let html = std::fs::read_to_string(done.join("report.html")).unwrap();
    assert!(
        html.contains("read from the manifest"),
        "the embedded fit is not used"
    );

    // a failed old run resumes to completion
    let dir = tmp.path().join("run");
    let out = simulate(
        &config("quick.toml"),
        &dir,
        &["--sim-fault", "table:trip@demand3"],
    );
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    make_format_1(&dir);
    let out = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--resume"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let m = manifest(&dir);
    assert_eq!(m["status"], "complete");
    assert_eq!(m["format_version"], 3);
    assert!(dir.join("fit.json").is_file() && dir.join("report.html").is_file());
    assert!(!dir.join(".lock").exists());
    let body = std::fs::read_to_string(dir.join("samples.csv")).unwrap();
    assert_eq!(body.lines().count(), 1 + 5 * 50);
    // the resumed session's rows in the file's own columns: counted from 0, no t_utc
    assert!(body.starts_with("step,index,t_s,rate_dps,volts,overload\n"));
    assert!(body.lines().any(|l| l.starts_with("4,49,")), "{body}");
    let steps = std::fs::read_to_string(dir.join("steps.csv")).unwrap();
    assert!(steps.starts_with("step_no,pass_no,"), "{steps}");
}

#[test]
fn a_fit_json_changed_after_the_run_is_flagged_by_the_report() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let out = simulate(&config("quick.toml"), &dir, &["--no-report"]);
    assert!(out.status.success(), "{}", text(&out));
    // an edit that keeps the document valid: the numbers may differ from the run's now
    let fit = std::fs::read_to_string(dir.join("fit.json")).unwrap();
    std::fs::write(dir.join("fit.json"), format!("{fit}\n")).unwrap();
    // refused: a report is not made from a fit.json the run did not write (exit 1)
    let out = gyrocal().arg("report").arg(&dir).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(text(&out).contains("fit.json CHANGED"), "{}", text(&out));
    assert!(!dir.join("report.html").exists());
    // made only when asked for, and then it says so
    let out = gyrocal()
        .args(["report", "--allow-modified"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("fit.json is not the file the run wrote"),
        "{err}"
    );
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("is not the file the run wrote"));
}

/// A completed run records SHA-256 of its data files; `gyrocal verify` finds an edited CSV
/// (exit 1, naming the file) and passes an untouched run.
#[test]
fn verify_catches_an_edited_csv() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/quick.toml");
    let out = gyrocal()
        .arg("run")
        .arg(&plan)
        .args(["--simulate", "--no-report", "-o"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let verify = || gyrocal().arg("verify").arg(&dir).output().unwrap();
    let ok = verify();
    let text = String::from_utf8_lossy(&ok.stdout).into_owned();
    assert_eq!(ok.status.code(), Some(0), "{text}");
    for f in ["samples.csv ok", "steps.csv ok", "fit.json ok"] {
        assert!(text.contains(f), "{f} in:\n{text}");
    }
    // one step's count of readings changed by hand
    let path = dir.join("steps.csv");
    let csv = std::fs::read_to_string(&path).unwrap();
    let edited = csv.replacen(",50,0,0,", ",49,0,0,", 1);
    assert_ne!(csv, edited, "a value to edit");
    std::fs::write(&path, edited).unwrap();
    let bad = verify();
    let text = String::from_utf8_lossy(&bad.stdout).into_owned();
    assert_eq!(bad.status.code(), Some(1), "{text}");
    assert!(text.contains("steps.csv CHANGED"), "{text}");
    assert!(text.contains("samples.csv ok"), "{text}");
}

/// The gyro under test and the run's context, as the operator entered them, are in the
/// manifest and on the report's first lines (not in the plan: its hash does not change), and a
/// resume refuses another gyro.
#[test]
fn the_gyro_under_test_is_recorded_and_a_resume_refuses_another() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let plan = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/quick.toml");
    let out = gyrocal()
        .arg("run")
        .arg(&plan)
        .args(["--simulate", "--sim-fault", "table:trip@demand3", "-o"])
        .arg(&dir)
        .args(["--dut-serial", "HRG-0421", "--dut-model", "HRG-50"])
        .args(["--operator", "A. Tester", "--ambient-c", "22.5"])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["dut"]["serial"], "HRG-0421", "{m}");
    assert_eq!(m["dut"]["model"], "HRG-50", "{m}");
    assert_eq!(m["context"]["operator"], "A. Tester", "{m}");
    assert_eq!(m["context"]["ambient_c"], 22.5, "{m}");

    // another gyro cannot continue this calibration; nothing is changed
    let out = gyrocal()
        .args(["run", "--simulate", "--resume"])
        .arg(&dir)
        .args(["--dut-serial", "HRG-0999"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("gyro serial HRG-0421") && err.contains("HRG-0999"),
        "{err}"
    );
    // the same gyro (or none named) continues it, and the report names it first
    let out = gyrocal()
        .args(["run", "--simulate", "--resume"])
        .arg(&dir)
        .args(["--dut-serial", "HRG-0421"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    let dut = html
        .find("serial <strong id=\"dut-serial\">HRG-0421</strong>")
        .expect("the certificate's head names the gyro");
    let first_number = html.find("id=\"summary\"").unwrap_or(html.len());
    assert!(dut < first_number, "the gyro is named before the results");
    assert!(
        html.contains("<tr><th>Operator</th><td>A. Tester</td></tr>"),
        "operator in the report"
    );
}
