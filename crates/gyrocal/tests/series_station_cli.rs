//! The station's `[chamber]` when a temperature series runs (`gyrocal run`): an overdue
//! chamber refuses the series, naming the station file and the key, unless `--allow-expired`,
//! which is recorded as a deviation; the controller that answers is compared with the record's
//! model (another is a warning and a deviation); the certificate names the chamber; a sweep
//! on the same station needs no `[chamber]` and is not refused for it.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::path::{Path, PathBuf};

use common::{between, config, gyrocal, json};

/// Bench 2 (meter and table due in 2099) with `chamber` appended.
fn station(dir: &Path, chamber: &str) -> PathBuf {
    let path = dir.join("station.toml");
    let text = format!("{}\n{chamber}", common::stations::bench_2(""));
    std::fs::write(&path, text).unwrap();
    path
}

/// An Espec's record, overdue since 2021: the series' plan drives a Watlow F4.
const ESPEC_OVERDUE: &str = "[chamber]\nmodel = \"Espec SH-641\"\nasset_id = \"TC-03\"\n\
    serial = \"S-1\"\ncertificate = \"C-3\"\ncalibrated = \"2020-01-01\"\ndue = \"2021-01-01\"\n";

fn run(plan: &str, station: &Path, out: &Path, extra: &[&str]) -> (Option<i32>, String) {
    let o = gyrocal()
        .arg("run")
        .arg(config(plan))
        .args(["--simulate", "--catalog", "off", "--station"])
        .arg(station)
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn an_overdue_chamber_refuses_a_series_naming_the_file_and_key_unless_allowed() {
    let tmp = tempfile::tempdir().unwrap();
    let station = station(tmp.path(), ESPEC_OVERDUE);
    let out = tmp.path().join("series");
    let (code, stderr) = run("series.toml", &station, &out, &[]);
    assert_eq!(code, Some(2), "{stderr}");
    let said = format!(
        "{}: [chamber] due = 2021-01-01: station bench-2: the chamber TC-03 was due for \
         calibration on 2021-01-01",
        station.display()
    );
    assert!(stderr.contains(&said), "{said}\nnot in\n{stderr}");
    assert!(stderr.contains("--allow-expired"), "{stderr}");
    assert!(
        !out.exists(),
        "nothing is created when the series is refused"
    );

    // allowed: the series runs, the departure and the other controller recorded
    let (code, stderr) = run("series.toml", &station, &out, &["--allow-expired"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains("the thermal chamber TC-03: station bench-2 names a Espec SH-641, but the controller that answered is a Watlow F4"),
        "{stderr}"
    );
    let manifest = json(&out, "manifest.json");
    let devs = manifest["deviations"].as_array().expect("deviations");
    let has = |kind: &str, text: &str| {
        devs.iter()
            .any(|d| d["kind"] == kind && d["text"].as_str().unwrap().contains(text))
    };
    assert!(has("expired-calibration", "the chamber TC-03"), "{devs:?}");
    assert!(
        has(gyrocal_files::station::SERIAL_MISMATCH, "Watlow F4"),
        "{devs:?}"
    );
    // the certificate names the chamber with the station's record and the controller's answer
    let html = std::fs::read_to_string(out.join("series.html")).unwrap();
    let table = between(&html, "id=\"instruments-table\"", "</table>");
    let row = between(table, "<tr><td>Thermal chamber</td>", "</tr>");
    for cell in [
        "Espec SH-641",
        "TC-03",
        "S-1",
        "C-3",
        "2021-01-01",
        "Watlow F4",
    ] {
        assert!(row.contains(cell), "{cell} not in {row}");
    }
}

#[test]
fn a_sweep_needs_no_chamber_and_is_not_refused_for_an_overdue_one() {
    let tmp = tempfile::tempdir().unwrap();
    // an overdue [chamber]: the sweep does not use it
    let overdue = station(tmp.path(), ESPEC_OVERDUE);
    let out = tmp.path().join("sweep");
    let (code, stderr) = run("quick.toml", &overdue, &out, &[]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stderr.contains("TC-03"), "{stderr}");
    let manifest = json(&out, "manifest.json");
    assert!(manifest.get("chamber").is_none(), "{manifest:#}");
    assert!(manifest.get("deviations").is_none(), "{manifest:#}");
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(!html.contains("Thermal chamber"));
    // no [chamber] at all: no word of it either
    let dir = tmp.path().join("plain");
    std::fs::create_dir(&dir).unwrap();
    let plain = station(&dir, "");
    let (code, stderr) = run("quick.toml", &plain, &tmp.path().join("sweep2"), &[]);
    assert_eq!(code, Some(0), "{stderr}");
    // (the checkout's own path may hold the word, as /work/wt-chamber did: not gyrocal's)
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .unwrap();
    let words = stderr.replace(&*root.to_string_lossy(), "<checkout>");
    assert!(!words.contains("chamber"), "{stderr}");
}

#[test]
fn a_series_on_a_chamber_the_record_names_says_so_and_records_no_deviation() {
    let tmp = tempfile::tempdir().unwrap();
    let station = station(
        tmp.path(),
        "[chamber]\nmodel = \"Thermotron SE-600 (Watlow F4)\"\nasset_id = \"TC-07\"\n\
         serial = \"SE600-1187\"\ncertificate = \"C-7\"\ncalibrated = \"2026-03-02\"\n\
         due = \"2099-03-02\"\n",
    );
    let out = tmp.path().join("series");
    let (code, stderr) = run("series.toml", &station, &out, &[]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains(
            "station: the thermal chamber's controller (Watlow F4) is the one station bench-2 names"
        ),
        "{stderr}"
    );
    let manifest = json(&out, "manifest.json");
    assert!(manifest.get("deviations").is_none(), "{manifest:#}");
}
