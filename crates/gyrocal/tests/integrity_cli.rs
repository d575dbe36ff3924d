//! The integrity checks check (issue 22, item 3) and a full disk is told as one (item 9),
//! through the binary: `gyrocal verify` fails a complete run whose checksums are missing and
//! covers the Allan results; `gyrocal report` refuses files that differ from the run's record
//! (or, with `--allow-modified`, says so on the report); no data file is read unless it is a
//! regular file; a write that fails for want of space leaves no temporary file, is worded by
//! what was written, and exits 1 (the environment), not 2 (bad input).

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, Instant};

use common::{config, gyrocal, json};

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A complete simulated run of configs/quick.toml without its report.
fn quick_run(tmp: &Path) -> PathBuf {
    let dir = tmp.join("run");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--no-report", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    dir
}

/// configs/drift.toml cut to 4 segments of 600 readings.
fn short_drift_plan(tmp: &Path) -> PathBuf {
    let plan = std::fs::read_to_string(config("drift.toml"))
        .unwrap()
        .replace("samples_per_rate = 3000", "samples_per_rate = 600")
        .replace("repeat = 167", "repeat = 4");
    let path = tmp.join("drift.toml");
    std::fs::write(&path, plan).unwrap();
    path
}

/// A complete simulated drift record (with its Allan analysis unless `no_report`).
fn drift_run(tmp: &Path, no_report: bool) -> PathBuf {
    let plan = short_drift_plan(tmp);
    let dir = tmp.join("drift");
    let mut c = gyrocal();
    c.arg("run")
        .arg(&plan)
        .args(["--simulate", "--out"])
        .arg(&dir);
    if no_report {
        c.arg("--no-report");
    }
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", text(&o));
    dir
}

fn verify(dir: &Path) -> Output {
    gyrocal().arg("verify").arg(dir).output().unwrap()
}

/// Runs `c`, killing it if it has not ended within `limit` (the test then fails): a read of
/// an endless file must be refused at once, never tried.
fn within(mut c: std::process::Command, limit: Duration) -> Output {
    let child = c
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let t0 = Instant::now();
    let waiter = std::thread::spawn(move || child.wait_with_output().unwrap());
    while !waiter.is_finished() {
        if t0.elapsed() > limit {
            let _ = std::process::Command::new("kill")
                .args(["-9", &pid.to_string()])
                .status();
            let _ = waiter.join();
            panic!("still running after {limit:?}: it reads the endless file");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    waiter.join().unwrap()
}

#[test]
fn verify_fails_a_complete_run_whose_manifest_lost_its_checksums() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = quick_run(tmp.path());
    let ok = verify(&dir);
    assert_eq!(ok.status.code(), Some(0), "{}", text(&ok));
    // the `checksums` key removed: the manifest still reads (it is optional in the format)
    let mut m = json(&dir, "manifest.json");
    assert!(m["checksums"]["steps.csv"].is_string());
    m.as_object_mut().unwrap().remove("checksums");
    std::fs::write(
        dir.join("manifest.json"),
        serde_json::to_vec_pretty(&m).unwrap(),
    )
    .unwrap();
    let bad = verify(&dir);
    let out = text(&bad);
    assert_eq!(bad.status.code(), Some(1), "{out}");
    assert!(
        out.contains("checksums of samples.csv and steps.csv are missing"),
        "{out}"
    );
    assert!(out.contains("steps.csv NOT RECORDED"), "{out}");
    // fit.json is still as recorded, and said so, but it does not make the run pass
    assert!(out.contains("fit.json ok"), "{out}");
    // the report is made (runs of gyrocal before checksums have none), and says the data
    // could not be checked
    let r = gyrocal().arg("report").arg(&dir).output().unwrap();
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains(
            "NOT CHECKED: manifest.json records no checksum of samples.csv and steps.csv"
        ) || html.contains("NOT CHECKED: manifest.json records no checksum of steps.csv"),
        "banner"
    );
    // and an emptied steps.csv is still found by the steps the manifest records as done
    let steps = dir.join("steps.csv");
    let csv = std::fs::read_to_string(&steps).unwrap();
    std::fs::write(&steps, format!("{}\n", csv.lines().next().unwrap())).unwrap();
    let r = gyrocal().arg("report").arg(&dir).output().unwrap();
    let out = text(&r);
    assert_eq!(r.status.code(), Some(1), "{out}");
    assert!(out.contains("steps.csv lacks"), "{out}");
}

#[test]
fn verify_fails_a_fit_json_whose_record_was_removed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = quick_run(tmp.path());
    let mut m = json(&dir, "manifest.json");
    m.as_object_mut().unwrap().remove("fit_summary");
    std::fs::write(
        dir.join("manifest.json"),
        serde_json::to_vec_pretty(&m).unwrap(),
    )
    .unwrap();
    let bad = verify(&dir);
    let out = text(&bad);
    assert_eq!(bad.status.code(), Some(1), "{out}");
    assert!(out.contains("fit.json NOT RECORDED"), "{out}");
    assert!(out.contains("steps.csv ok"), "{out}");
}

#[test]
fn report_refuses_a_complete_run_whose_steps_csv_was_emptied_or_banners_it_when_allowed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = quick_run(tmp.path());
    let steps = dir.join("steps.csv");
    let csv = std::fs::read_to_string(&steps).unwrap();
    let header = csv.lines().next().unwrap();
    std::fs::write(&steps, format!("{header}\n")).unwrap();
    let r = gyrocal().arg("report").arg(&dir).output().unwrap();
    let err = text(&r);
    assert_eq!(r.status.code(), Some(1), "{err}");
    assert!(
        err.contains("steps.csv CHANGED since the run recorded it"),
        "{err}"
    );
    assert!(err.contains("--allow-modified"), "{err}");
    assert!(
        !dir.join("report.html").exists(),
        "no certificate from fit.json"
    );
    // the same with --acceptance: still refused
    let r = gyrocal()
        .arg("report")
        .arg(&dir)
        .arg("--acceptance")
        .arg(config("acceptance.example.toml"))
        .output()
        .unwrap();
    assert_eq!(r.status.code(), Some(1), "{}", text(&r));
    // allowed: made, with a banner naming the file, and the warning on the terminal
    let r = gyrocal()
        .args(["report", "--allow-modified"])
        .arg(&dir)
        .output()
        .unwrap();
    let err = text(&r);
    assert_eq!(r.status.code(), Some(0), "{err}");
    assert!(err.contains("MODIFIED SINCE THE RUN: steps.csv"), "{err}");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(
        html.contains("MODIFIED SINCE THE RUN: steps.csv CHANGED"),
        "banner"
    );
}

#[test]
fn verify_and_report_refuse_a_samples_csv_linked_to_dev_zero_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = drift_run(tmp.path(), true);
    let samples = dir.join("samples.csv");
    std::fs::rename(&samples, dir.join("samples.csv.orig")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &samples).unwrap();
    let mut c = gyrocal();
    c.arg("verify").arg(&dir);
    let o = within(c, Duration::from_secs(20));
    let out = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("samples.csv UNREADABLE") && out.contains("a character device"),
        "{out}"
    );
    assert!(out.contains("steps.csv ok"), "{out}");
    let mut c = gyrocal();
    c.arg("report").arg(&dir);
    let o = within(c, Duration::from_secs(20));
    let out = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("samples.csv") && out.contains("not a regular file"),
        "{out}"
    );
    assert!(!dir.join("allan.json").exists());
}

#[test]
fn the_allan_results_are_recorded_and_an_edited_allan_json_fails_verify_and_report() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = drift_run(tmp.path(), false);
    let m = json(&dir, "manifest.json");
    for f in ["allan.json", "allan.html", "samples.csv", "steps.csv"] {
        assert!(m["checksums"][f].is_string(), "{f} recorded: {m:#}");
    }
    let ok = verify(&dir);
    let out = text(&ok);
    assert_eq!(ok.status.code(), Some(0), "{out}");
    assert!(
        out.contains("allan.json ok") && out.contains("allan.html ok"),
        "{out}"
    );
    assert!(!dir.join(".lock").exists(), "a finished run keeps no lock");
    // one figure of the analysis edited
    let path = dir.join("allan.json");
    let a = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, a.replacen("\"rows\": ", "\"rows\": 1", 1)).unwrap();
    let bad = verify(&dir);
    let out = text(&bad);
    assert_eq!(bad.status.code(), Some(1), "{out}");
    assert!(out.contains("allan.json CHANGED"), "{out}");
    // the report does not silently replace an edited analysis
    let r = gyrocal().arg("report").arg(&dir).output().unwrap();
    let out = text(&r);
    assert_eq!(r.status.code(), Some(1), "{out}");
    assert!(out.contains("allan.json CHANGED"), "{out}");
    // allowed: the analysis is written again (recorded anew), its page says what differed
    let r = gyrocal()
        .args(["report", "--allow-modified"])
        .arg(&dir)
        .output()
        .unwrap();
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    let page = std::fs::read_to_string(dir.join("allan.html")).unwrap();
    assert!(
        page.contains("MODIFIED SINCE THE RUN: allan.json CHANGED"),
        "banner"
    );
    let ok = verify(&dir);
    assert_eq!(ok.status.code(), Some(0), "{}", text(&ok));
    assert!(!dir.join(".lock").exists());
    // an analysis an earlier gyrocal wrote without a record: verify fails it, and the report
    // (no flag needed: nothing recorded differs) writes it again, recorded
    let mut m = json(&dir, "manifest.json");
    m["checksums"].as_object_mut().unwrap().remove("allan.json");
    std::fs::write(
        dir.join("manifest.json"),
        serde_json::to_vec_pretty(&m).unwrap(),
    )
    .unwrap();
    let bad = verify(&dir);
    let out = text(&bad);
    assert_eq!(bad.status.code(), Some(1), "{out}");
    assert!(out.contains("allan.json NOT RECORDED"), "{out}");
    let r = gyrocal().arg("report").arg(&dir).output().unwrap();
    assert_eq!(r.status.code(), Some(0), "{}", text(&r));
    let ok = verify(&dir);
    assert_eq!(ok.status.code(), Some(0), "{}", text(&ok));
}

#[test]
fn a_full_disk_while_writing_the_allan_page_leaves_no_temporary_file_and_says_what_was_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = drift_run(tmp.path(), true);
    // the page's temporary file is a link to /dev/full: writing it fails with ENOSPC
    let tmp_page = dir.join(".allan.html.tmp");
    std::os::unix::fs::symlink("/dev/full", &tmp_page).unwrap();
    let r = gyrocal().arg("report").arg(&dir).output().unwrap();
    let out = text(&r);
    assert_eq!(
        r.status.code(),
        Some(1),
        "a full disk is not bad input: {out}"
    );
    assert!(
        out.contains("No space left on device") && out.contains(".allan.html.tmp"),
        "{out}"
    );
    assert!(
        out.contains("written:") && out.contains("allan.json"),
        "{out}"
    );
    assert!(
        std::fs::symlink_metadata(&tmp_page).is_err(),
        "the temporary file is removed"
    );
    assert!(!dir.join("allan.html").exists());
    // what was written is recorded: allan.json verifies, nothing else is claimed
    let m = json(&dir, "manifest.json");
    assert!(m["checksums"]["allan.json"].is_string());
    assert!(m["checksums"].get("allan.html").is_none());
    let v = verify(&dir);
    let out = text(&v);
    assert_eq!(v.status.code(), Some(0), "{out}");
    assert!(out.contains("allan.json ok"), "{out}");
}

/// A file system that takes no more bytes when a run starts (RLIMIT_FSIZE 0: every write to a
/// file fails with EFBIG, as a full disk fails with ENOSPC) is a failure of the environment:
/// exit 1, not 2, and the half-created run directory is removed.
#[test]
fn a_run_that_cannot_write_its_first_file_exits_1_and_leaves_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let script = "trap '' XFSZ; ulimit -f 0; exec \"$0\" \"$@\"";
    let base = gyrocal();
    let mut sh = std::process::Command::new("sh");
    sh.arg("-c").arg(script).arg(base.get_program());
    for (k, v) in base.get_envs() {
        match v {
            Some(v) => sh.env(k, v),
            None => sh.env_remove(k),
        };
    }
    let o = sh
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--no-report", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let out = text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("samples.csv") || out.contains("manifest"),
        "{out}"
    );
    assert!(!dir.exists(), "the run directory it created is removed");
}
