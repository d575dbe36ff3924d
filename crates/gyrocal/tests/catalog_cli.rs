//! The calibration catalog as a user drives it: simulated calibrations by `gyrocal run`,
//! `gyrocal catalog import`/`rebuild`, `gyrocal runs` and `gyrocal history` on the default
//! SQLite catalog (in a temporary XDG_DATA_HOME) and, when GYROCAL_TEST_POSTGRES_URL is set,
//! on PostgreSQL.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::Path;
use std::process::Output;

use common::config;
/// The binary with none of the user's files, its default catalog in the test's `data_home`.
use common::gyrocal_with_data_home as gyrocal;

fn ok(out: &Output) -> String {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    stdout
}

/// A simulated calibration that is not indexed by the run itself (the tests import it).
fn calibrate(data_home: &Path, dir: &Path, serial: &str) {
    ok(&gyrocal(data_home)
        .args([
            "run",
            "--simulate",
            "--catalog",
            "off",
            "--dut-serial",
            serial,
            "--out",
        ])
        .arg(dir)
        .arg(config("quick.toml"))
        .output()
        .unwrap());
}

fn json(out: &Output) -> serde_json::Value {
    serde_json::from_str(&ok(out)).unwrap()
}

/// Imports three calibrations and checks what `runs` and `history` say, with `extra` args
/// (a `--catalog`) on each catalog command.
/// `tag` makes the serials unique on a shared catalog.
fn exercise(data_home: &Path, root: &Path, extra: &[&str], tag: &str) {
    let (s1, s2) = (format!("0421{tag}"), format!("0777{tag}"));
    let runs = root.join("runs");
    calibrate(data_home, &runs.join("a1"), &s1);
    calibrate(data_home, &runs.join("a2"), &s1);
    calibrate(data_home, &runs.join("b1"), &s2);
    let not_a_run = root.join("empty");
    std::fs::create_dir_all(&not_a_run).unwrap();

    let out = gyrocal(data_home)
        .args(["catalog", "import"])
        .args(extra)
        .arg(runs.join("a1"))
        .arg(runs.join("a2"))
        .arg(&not_a_run)
        .output()
        .unwrap();
    let stdout = ok(&out);
    assert!(stdout.contains("2 run(s) imported"), "{stdout}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("skipped") && stderr.contains("empty"),
        "{stderr}"
    );
    // rebuild finds all three (and importing again duplicates nothing)
    ok(&gyrocal(data_home)
        .args(["catalog", "rebuild"])
        .args(extra)
        .arg(&runs)
        .output()
        .unwrap());
    ok(&gyrocal(data_home)
        .args(["catalog", "import"])
        .args(extra)
        .arg(runs.join("b1"))
        .output()
        .unwrap());

    let list = json(
        &gyrocal(data_home)
            .args(["runs", "--json"])
            .args(extra)
            .output()
            .unwrap(),
    );
    let list = list.as_array().unwrap();
    let ours: Vec<&serde_json::Value> = list
        .iter()
        .filter(|r| {
            r["directory"]
                .as_str()
                .unwrap()
                .starts_with(std::fs::canonicalize(&runs).unwrap().to_str().unwrap())
        })
        .collect();
    assert_eq!(ours.len(), 3, "{list:?}");
    for r in &ours {
        assert_eq!(r["status"], "complete");
        assert_eq!(r["simulated"], true);
        let k = r["results"]["scale_factor"].as_f64().unwrap();
        assert!(k > 0.0, "{r}");
    }
    // newest first
    assert!(ours[0]["started_utc"].as_str() >= ours[1]["started_utc"].as_str());

    let only = json(
        &gyrocal(data_home)
            .args(["runs", "--json", "--serial", &s2])
            .args(extra)
            .output()
            .unwrap(),
    );
    assert_eq!(only.as_array().unwrap().len(), 1);

    let h = json(
        &gyrocal(data_home)
            .args(["history", &s1, "--json", "--include-simulated"])
            .args(extra)
            .output()
            .unwrap(),
    );
    let cals = h["calibrations"].as_array().unwrap();
    assert_eq!(cals.len(), 2, "{h}");
    for c in cals {
        assert_eq!(c["dut_serial"], s1.as_str());
        assert!(c["results"]["scale_factor"].as_f64().unwrap() > 0.0);
        assert!(c["results"]["bias_dph"].is_number());
    }
    assert!(h["repeatability"]["scale_factor_ppm"].is_number(), "{h}");
    // simulated runs are left out unless asked for
    let h = json(
        &gyrocal(data_home)
            .args(["history", &s1, "--json"])
            .args(extra)
            .output()
            .unwrap(),
    );
    assert_eq!(h["calibrations"].as_array().unwrap().len(), 0);
    // the HTML page with its plots
    let html = root.join("h.html");
    ok(&gyrocal(data_home)
        .args(["history", &s1, "--include-simulated", "-o"])
        .arg(&html)
        .args(extra)
        .output()
        .unwrap());
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("<svg") && page.contains(&s1));
}

#[test]
fn runs_and_history_on_the_default_sqlite_catalog() {
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    exercise(&data_home, tmp.path(), &[], "");
    assert!(data_home.join("gyrocal/catalog.sqlite").is_file());
    // the table
    let out = ok(&gyrocal(&data_home).args(["runs"]).output().unwrap());
    assert!(out.contains("0421") && out.contains("0777"), "{out}");
}

#[test]
fn runs_and_history_on_postgres() {
    let Some(url) = common::postgres_url() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    let tag = format!("-{}", std::process::id());
    exercise(&data_home, tmp.path(), &["--catalog", &url], &tag);
    assert!(!data_home.join("gyrocal/catalog.sqlite").exists());
    // a run indexes itself in the lab's PostgreSQL as it goes
    let serial = format!("0999{tag}");
    let doc = json(
        &gyrocal(&data_home)
            .args(["run", "--simulate", "--json", "--dut-serial", &serial])
            .args(["--catalog", &url, "--out"])
            .arg(tmp.path().join("live"))
            .arg(config("quick.toml"))
            .output()
            .unwrap(),
    );
    assert_eq!(doc["catalog"]["updated"], true, "{doc:#}");
    let list = json(
        &gyrocal(&data_home)
            .args(["runs", "--json", "--catalog", &url, "--serial", &serial])
            .output()
            .unwrap(),
    );
    let list = list.as_array().unwrap();
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!(list[0]["status"], "complete");
}

#[test]
fn a_bad_catalog_url_is_bad_input_and_hides_the_password() {
    let tmp = tempfile::tempdir().unwrap();
    let out = gyrocal(tmp.path())
        .args(["runs", "--catalog", "mysql://lab:topsecret@db/x"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("topsecret"), "{stderr}");
    assert!(stderr.contains("lab:***@db"), "{stderr}");
}

#[test]
fn a_run_indexes_itself_and_a_dead_catalog_never_stops_it() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let url = format!("sqlite:{}", tmp.path().join("lab.sqlite").display());
    let dir = tmp.path().join("r1");
    let doc = json(
        &gyrocal(&data)
            .args(["run", "--simulate", "--json", "--dut-serial", "0421"])
            .args(["--catalog", &url, "--out"])
            .arg(&dir)
            .arg(config("quick.toml"))
            .output()
            .unwrap(),
    );
    assert_eq!(doc["catalog"]["updated"], true, "{doc:#}");
    // in the catalog without an import, with its final state and results
    let list = json(
        &gyrocal(&data)
            .args(["runs", "--json", "--catalog", &url])
            .output()
            .unwrap(),
    );
    let list = list.as_array().unwrap();
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!(list[0]["status"], "complete");
    assert_eq!(list[0]["dut_serial"], "0421");
    assert!(list[0]["results"]["scale_factor"].as_f64().unwrap() > 0.0);

    // a catalog nobody answers on: the run completes all the same, and says so
    let dead = "postgres://gyrocal@127.0.0.1:1/nowhere";
    let dir2 = tmp.path().join("r2");
    let t0 = std::time::Instant::now();
    let out = gyrocal(&data)
        .args(["run", "--simulate", "--json", "--dut-serial", "0421"])
        .args(["--catalog", dead, "--out"])
        .arg(&dir2)
        .arg(config("quick.toml"))
        .output()
        .unwrap();
    let took = t0.elapsed();
    let doc = json(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(doc["status"], "complete");
    assert_eq!(doc["table"]["at_rest"], true, "{doc:#}");
    assert_eq!(doc["catalog"]["updated"], false);
    assert!(stderr.contains("gyrocal catalog import"), "{stderr}");
    assert!(
        took < std::time::Duration::from_secs(20),
        "bounded wait at the end: {took:?}"
    );
    // an import brings the catalog up to date from the run directory
    ok(&gyrocal(&data)
        .args(["catalog", "import", "--catalog", &url])
        .arg(&dir2)
        .output()
        .unwrap());
    let list = json(
        &gyrocal(&data)
            .args(["runs", "--json", "--catalog", &url, "--serial", "0421"])
            .output()
            .unwrap(),
    );
    assert_eq!(list.as_array().unwrap().len(), 2, "{list}");
}

/// Starts `n` simulated calibrations at once, each indexing itself in `url`; waits for all.
fn concurrent_runs(data_home: &Path, root: &Path, url: &str, serials: &[String]) {
    let children: Vec<_> = serials
        .iter()
        .map(|s| {
            gyrocal(data_home)
                .args(["run", "--simulate", "--json", "--dut-serial", s])
                .args(["--catalog", url, "--out"])
                .arg(root.join(s))
                .arg(config("quick.toml"))
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for c in children {
        let doc = json(&c.wait_with_output().unwrap());
        assert_eq!(doc["catalog"]["updated"], true, "{doc:#}");
    }
    for s in serials {
        let list = json(
            &gyrocal(data_home)
                .args(["runs", "--json", "--catalog", url, "--serial", s])
                .output()
                .unwrap(),
        );
        let list = list.as_array().unwrap();
        assert_eq!(
            list.len(),
            1,
            "one row for {s}, none lost or doubled: {list:?}"
        );
        assert_eq!(list[0]["status"], "complete");
    }
}

#[test]
fn two_gyrocal_processes_index_one_sqlite_catalog() {
    let tmp = tempfile::tempdir().unwrap();
    let url = format!("sqlite:{}", tmp.path().join("shared.sqlite").display());
    let serials: Vec<String> = (1..=2).map(|i| format!("SQ-{i}")).collect();
    concurrent_runs(&tmp.path().join("data"), tmp.path(), &url, &serials);
    let all = json(
        &gyrocal(&tmp.path().join("data"))
            .args(["runs", "--json", "--catalog", &url])
            .output()
            .unwrap(),
    );
    assert_eq!(all.as_array().unwrap().len(), 2, "{all}");
}

#[test]
fn four_gyrocal_processes_index_one_postgres_catalog() {
    let Some(url) = common::postgres_url() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let serials: Vec<String> = (1..=4)
        .map(|i| format!("PG-{i}-{}", std::process::id()))
        .collect();
    concurrent_runs(&tmp.path().join("data"), tmp.path(), &url, &serials);
}

#[test]
fn a_catalog_killed_during_a_run_lets_it_complete_and_an_import_catches_up() {
    let Some(url) = common::postgres_url() else {
        return;
    };
    // the catalog server's network path: a relay that cuts every connection, as a stopped
    // server would
    let proxy = common::serve::Relay::to(&url);
    let via = proxy.url.clone();
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let serial = format!("KILL-{}", std::process::id());
    let dir = tmp.path().join("run");
    // paced, so the run lasts a few seconds of wall time
    let child = gyrocal(&data)
        .args(["run", "--simulate", "--sim-time-scale", "40", "--json"])
        .args(["--dut-serial", &serial, "--catalog", &via, "--out"])
        .arg(&dir)
        .arg(config("quick.toml"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // wait until the catalog has the run (registered and updated as it goes)
    let t0 = std::time::Instant::now();
    let seen_running = loop {
        let list = json(
            &gyrocal(&data)
                .args(["runs", "--json", "--catalog", &url, "--serial", &serial])
                .output()
                .unwrap(),
        );
        if let Some(r) = list.as_array().and_then(|l| l.first()) {
            break r["status"].clone();
        }
        assert!(
            t0.elapsed() < std::time::Duration::from_secs(30),
            "never indexed"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    assert_eq!(seen_running, "running");
    proxy.cut();
    std::thread::sleep(std::time::Duration::from_millis(50));
    let out = child.wait_with_output().unwrap();
    let doc = json(&out);
    assert_eq!(
        doc["status"], "complete",
        "the run completes without its catalog"
    );
    assert_eq!(doc["table"]["at_rest"], true, "{doc:#}");
    assert_eq!(doc["catalog"]["updated"], false, "{doc:#}");
    let list = json(
        &gyrocal(&data)
            .args(["runs", "--json", "--catalog", &url, "--serial", &serial])
            .output()
            .unwrap(),
    );
    assert_eq!(
        list[0]["status"], "running",
        "the catalog missed the end: {list}"
    );
    // the run directory is the source of truth: an import brings the row up to date
    ok(&gyrocal(&data)
        .args(["catalog", "import", "--catalog", &url])
        .arg(&dir)
        .output()
        .unwrap());
    let list = json(
        &gyrocal(&data)
            .args(["runs", "--json", "--catalog", &url, "--serial", &serial])
            .output()
            .unwrap(),
    );
    let list = list.as_array().unwrap();
    assert_eq!(list.len(), 1, "{list:?}");
    assert_eq!(list[0]["status"], "complete");
    assert!(list[0]["results"]["scale_factor"].as_f64().unwrap() > 0.0);
}

/// A short simulated drift run (configs/drift.toml, 40 segments ≈ 44 min) that indexes itself
/// in the catalog, then its history: the drift figures are there, with their uncertainty.
fn drift_history(data_home: &Path, root: &Path, extra: &[&str], tag: &str) {
    let serial = format!("DRIFT{tag}");
    let plan = root.join("drift.toml");
    std::fs::write(
        &plan,
        std::fs::read_to_string(config("drift.toml"))
            .unwrap()
            .replace("repeat = 167", "repeat = 40"),
    )
    .unwrap();
    let doc = json(
        &gyrocal(data_home)
            .args(["run", "--simulate", "--json", "--dut-serial", &serial])
            .args(extra)
            .arg("--out")
            .arg(root.join("drift-run"))
            .arg(&plan)
            .output()
            .unwrap(),
    );
    assert_eq!(doc["catalog"]["updated"], true, "{doc:#}");
    let h = json(
        &gyrocal(data_home)
            .args(["history", &serial, "--include-simulated", "--json"])
            .args(extra)
            .output()
            .unwrap(),
    );
    let cals = h["calibrations"].as_array().unwrap();
    assert_eq!(cals.len(), 1, "{h:#}");
    assert_eq!(cals[0]["kind"], "drift");
    let r = &cals[0]["results"];
    // configs/drift.toml's gyro: N 0.02 °/√h, B 1 °/h; within the expanded uncertainty (k = 2)
    for (key, set) in [("arw_deg_rt_h", 0.02), ("bias_instability_dph", 1.0)] {
        let v = r[key].as_f64().unwrap_or_else(|| panic!("{key} in {r}"));
        let u = r[format!("u_{key}")].as_f64().unwrap();
        assert!((v - set).abs() <= u, "{key}: {v} ± {u} (k = 2), set {set}");
    }
    // the Earth rate of the plan's axis and latitude is out of the catalogued bias
    let bias = r["drift_bias_dph"].as_f64().unwrap();
    assert!((bias - 0.0088 / 0.3612 * 3600.0).abs() < 10.0, "{bias}");
    assert!(
        r["scale_factor"].is_null(),
        "a drift test fits no scale factor"
    );
    let trends: Vec<&str> = h["trends"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|t| t["quantity"].as_str().or_else(|| t["name"].as_str()))
        .collect();
    assert!(trends.contains(&"arw_deg_rt_h"), "{trends:?}");
    let text = ok(&gyrocal(data_home)
        .args(["history", &serial, "--include-simulated"])
        .args(extra)
        .output()
        .unwrap());
    assert!(text.contains("drift tests:"), "{text}");
    let page = root.join("history.html");
    ok(&gyrocal(data_home)
        .args(["history", &serial, "--include-simulated", "-o"])
        .arg(&page)
        .args(extra)
        .output()
        .unwrap());
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("<h2>Drift tests</h2>"), "drift table");
    assert!(
        !html.contains("<h2>Calibrations</h2>"),
        "no empty sweep table"
    );
}

#[test]
fn a_drift_test_is_catalogued_with_its_noise_terms() {
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    drift_history(&data_home, tmp.path(), &[], "");
}

#[test]
fn a_drift_test_is_catalogued_with_its_noise_terms_on_postgres() {
    let Some(url) = common::postgres_url() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    let tag = format!("-{}", std::process::id());
    drift_history(&data_home, tmp.path(), &["--catalog", &url], &tag);
}

/// Output of a command expected to fail with `code`: its stderr.
fn fails(out: &Output, code: i32) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(code),
        "{}\n{stderr}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

/// The offset and size of the page of the SQLite `file` that holds the `runs` rows of a
/// serial: the first table b-tree leaf page (type 0x0D) after the schema page where `needle`
/// occurs at least `n` times.
fn page_of_rows(file: &[u8], needle: &[u8], n: usize) -> (usize, usize) {
    let size = match u16::from_be_bytes([file[16], file[17]]) {
        1 => 65536,
        s => usize::from(s),
    };
    for (i, page) in file.chunks(size).enumerate().skip(1) {
        let count = page.windows(needle.len()).filter(|w| *w == needle).count();
        if page[0] == 0x0D && count >= n {
            return (i * size, size);
        }
    }
    panic!("no page of the catalog holds {n} rows of {needle:?}");
}

/// `len` pseudo-random bytes (xorshift64 from `seed`): the same every run.
fn random_bytes(seed: u64, len: usize) -> Vec<u8> {
    let mut x = seed;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x.to_le_bytes()[3]
        })
        .collect()
}

/// The complete calibrations `gyrocal history SERIAL` lists from `catalog`.
fn history_len(data_home: &Path, catalog: &str, serial: &str) -> usize {
    let h = json(
        &gyrocal(data_home)
            .args(["history", serial, "--json", "--include-simulated"])
            .args(["--catalog", catalog])
            .output()
            .unwrap(),
    );
    h["calibrations"].as_array().unwrap().len()
}

/// Four simulated calibrations of `serial` under `runs`, rebuilt into the SQLite file
/// `file`; returns the file's bytes and the offset and size of the page holding the rows.
fn catalog_of_four(data: &Path, runs: &Path, file: &Path, serial: &str) -> (Vec<u8>, usize, usize) {
    for i in 1..=4 {
        calibrate(data, &runs.join(format!("c{i}")), serial);
    }
    let url = format!("sqlite:{}", file.display());
    let out = ok(&gyrocal(data)
        .args(["catalog", "rebuild", "--catalog", &url])
        .arg(runs)
        .output()
        .unwrap());
    assert!(out.contains("4 run(s) imported"), "{out}");
    assert_eq!(history_len(data, &url, serial), 4);
    // the catalog closed whole: its rows are in the file, not left in a -wal file
    let mut wal = file.as_os_str().to_os_string();
    wal.push("-wal");
    assert!(
        std::fs::metadata(&wal).map_or(0, |m| m.len()) == 0,
        "rows left in {wal:?}"
    );
    let bytes = std::fs::read(file).unwrap();
    let (page, size) = page_of_rows(&bytes, serial.as_bytes(), 4);
    (bytes, page, size)
}

/// Every listing of the damaged `file` exits 1, lists nothing, and names the file, the
/// damage and the rebuild.
fn listings_refuse(data: &Path, file: &Path, serial: &str) {
    let url = format!("sqlite:{}", file.display());
    for args in [
        vec!["history", serial, "--include-simulated"],
        vec!["history", serial, "--json"],
        vec!["runs"],
        vec!["runs", "--serial", serial],
    ] {
        let out = gyrocal(data)
            .args(&args)
            .args(["--catalog", &url])
            .output()
            .unwrap();
        let err = fails(&out, 1);
        assert!(out.stdout.is_empty(), "{args:?}: nothing listed");
        assert!(
            err.contains(&file.display().to_string())
                && err.contains("damaged")
                && err.contains("gyrocal catalog rebuild"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn a_garbled_row_is_never_read_as_a_shorter_history() {
    // The issue's case: random bytes over one run's status in the page of the rows. SQLite's
    // own checks find nothing (the page is well formed), and a history that filtered on
    // `complete` in SQL showed 3 of the 4 calibrations and exited 0.
    let tmp = tempfile::tempdir().unwrap();
    let (data, runs) = (tmp.path().join("data"), tmp.path().join("runs"));
    let file = tmp.path().join("lab").join("catalog.sqlite");
    let serial = "DMG-0421";
    let (mut bytes, page, size) = catalog_of_four(&data, &runs, &file, serial);
    let rows = &bytes[page..page + size];
    let second = rows
        .windows(8)
        .enumerate()
        .filter(|(_, w)| *w == b"complete")
        .map(|(i, _)| page + i)
        .nth(1)
        .expect("four rows say complete");
    bytes[second..second + 8].copy_from_slice(&random_bytes(0x9E37_79B9_7F4A_7C15, 8));
    std::fs::write(&file, &bytes).unwrap();
    listings_refuse(&data, &file, serial);
    // the rebuild replaces every row from the run directories
    let url = format!("sqlite:{}", file.display());
    let out = ok(&gyrocal(&data)
        .args(["catalog", "rebuild", "--catalog", &url])
        .arg(&runs)
        .output()
        .unwrap());
    assert!(out.contains("4 run(s) imported"), "{out}");
    assert_eq!(history_len(&data, &url, serial), 4);
}

#[test]
fn a_damaged_page_is_refused_and_the_rebuild_sets_it_aside_and_recovers_every_calibration() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, runs) = (tmp.path().join("data"), tmp.path().join("runs"));
    let lab = tmp.path().join("lab");
    let file = lab.join("catalog.sqlite");
    let serial = "DMG-0777";
    let (mut bytes, page, size) = catalog_of_four(&data, &runs, &file, serial);
    // random bytes over the middle of the rows' cells: SQLite finds the page malformed
    let content = match u16::from_be_bytes([bytes[page + 5], bytes[page + 6]]) {
        0 => 65536,
        c => usize::from(c),
    };
    let at = page + content + (size - content) / 2 - 128;
    bytes[at..at + 256].copy_from_slice(&random_bytes(0x2545_F491_4F6C_DD1D, 256));
    std::fs::write(&file, &bytes).unwrap();
    listings_refuse(&data, &file, serial);

    // the rebuild moves the damaged file aside (kept as it was) and recovers all four
    let url = format!("sqlite:{}", file.display());
    let out = gyrocal(&data)
        .args(["catalog", "rebuild", "--catalog", &url])
        .arg(&runs)
        .output()
        .unwrap();
    let stdout = ok(&out);
    assert!(stdout.contains("4 run(s) imported"), "{stdout}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("is damaged") && stderr.contains("moved it aside to"),
        "{stderr}"
    );
    let kept: Vec<_> = std::fs::read_dir(&lab)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| {
            n.starts_with("catalog.sqlite.damaged-") && !n.ends_with("-wal") && !n.ends_with("-shm")
        })
        .collect();
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert!(stderr.contains(&kept[0]), "{stderr}");
    assert_eq!(
        std::fs::read(lab.join(&kept[0])).unwrap(),
        bytes,
        "the damaged file is kept as it was"
    );
    assert_eq!(history_len(&data, &url, serial), 4);
    // a sound catalog is rebuilt in place, nothing moved
    let out = gyrocal(&data)
        .args(["catalog", "rebuild", "--catalog", &url])
        .arg(&runs)
        .output()
        .unwrap();
    ok(&out);
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("damaged"),
        "{out:?}"
    );
}

#[test]
fn a_listing_creates_no_catalog_and_says_there_is_none() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let nowhere = tmp.path().join("a").join("b").join("c.sqlite");
    let url = format!("sqlite:{}", nowhere.display());
    for args in [
        vec!["runs", "--catalog", &url],
        vec!["history", "0421", "--catalog", &url],
        vec!["runs", "--json", "--catalog", &url],
    ] {
        let err = fails(&gyrocal(&data).args(&args).output().unwrap(), 2);
        assert!(
            err.contains(&format!("no catalog at {}", nowhere.display())),
            "{args:?}: {err}"
        );
        assert!(
            !tmp.path().join("a").exists(),
            "{args:?} created directories"
        );
    }
    // the default catalog likewise: nothing is created in the data directory
    let err = fails(&gyrocal(&data).args(["runs"]).output().unwrap(), 2);
    let default = data.join("gyrocal").join("catalog.sqlite");
    assert!(
        err.contains(&format!("no catalog at {}", default.display())),
        "{err}"
    );
    assert!(!data.exists(), "runs created {}", data.display());
    let err = fails(
        &gyrocal(&data).args(["history", "0421"]).output().unwrap(),
        2,
    );
    assert!(err.contains("no catalog at"), "{err}");
    assert!(!data.exists(), "history created {}", data.display());
    // a run or an import creates it; then the listing works
    calibrate(&data, &tmp.path().join("r"), "0421");
    ok(&gyrocal(&data)
        .args(["catalog", "import"])
        .arg(tmp.path().join("r"))
        .output()
        .unwrap());
    let out = ok(&gyrocal(&data).args(["runs"]).output().unwrap());
    assert!(out.contains("0421"), "{out}");
}

#[test]
fn a_closed_postgres_port_is_said_at_once_with_host_and_port() {
    // a port nobody listens on: bound, then released
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let tmp = tempfile::tempdir().unwrap();
    let url = format!("postgres://gyrocal:hunter2@127.0.0.1:{port}/lab");
    for args in [vec!["runs"], vec!["history", "0421"]] {
        let t0 = std::time::Instant::now();
        let out = gyrocal(tmp.path())
            .args(&args)
            .args(["--catalog", &url])
            .output()
            .unwrap();
        let took = t0.elapsed();
        let err = fails(&out, 1);
        assert!(
            err.contains("connection refused") && err.contains(&format!("127.0.0.1:{port}")),
            "{args:?}: {err}"
        );
        assert!(!err.contains("pool timed out"), "{err}");
        assert!(!err.contains("hunter2"), "{err}");
        // the pool alone took its 5 s acquire timeout to say only "timed out"
        assert!(
            took < std::time::Duration::from_secs(3),
            "{args:?} took {took:?}"
        );
    }
}

#[test]
fn a_test_run_of_the_binary_sees_none_of_the_users_files() {
    // tests/common removes every variable through which gyrocal finds a user's files, and a
    // run indexes itself nowhere; under CI these variables point at a sentinel (.ci/run)
    let cmd = common::gyrocal();
    let envs: std::collections::HashMap<_, _> = cmd.get_envs().collect();
    for (name, _) in std::env::vars_os() {
        let text = name.to_string_lossy();
        if text == "GYROCAL_CATALOG" {
            continue;
        }
        if text == "HOME" || text.starts_with("XDG_") || text.starts_with("GYROCAL_") {
            assert_eq!(
                envs.get(name.as_os_str()),
                Some(&None),
                "{text} reaches the binary"
            );
        }
    }
    assert_eq!(
        envs.get(std::ffi::OsStr::new("GYROCAL_CATALOG")),
        Some(&Some(std::ffi::OsStr::new("off")))
    );
    let tmp = tempfile::tempdir().unwrap();
    let out = common::gyrocal()
        .args(["run", "--simulate", "--json", "--out"])
        .arg(tmp.path().join("run"))
        .arg(config("quick.toml"))
        .output()
        .unwrap();
    let doc = json(&out);
    assert_eq!(doc["status"], "complete");
    assert!(doc["catalog"].is_null(), "the run was indexed: {doc:#}");
}

/// A simulated calibration of the plan `text` (written beside `dir`), not indexed by the run.
fn calibrate_plan(data_home: &Path, dir: &Path, serial: &str, text: &str) {
    let plan = dir.with_extension("toml");
    std::fs::create_dir_all(dir.parent().unwrap()).unwrap();
    std::fs::write(&plan, text).unwrap();
    ok(&gyrocal(data_home)
        .args([
            "run",
            "--simulate",
            "--catalog",
            "off",
            "--dut-serial",
            serial,
        ])
        .arg("--out")
        .arg(dir)
        .arg(&plan)
        .output()
        .unwrap());
}

/// Issue 25: a different simulation seed is not a different plan (two seeds of quick.toml
/// give a repeatability and no warning); a different rate list is, and is left out of the
/// repeatability with a warning naming the plans.
#[test]
fn history_tells_plans_apart_by_their_rates_not_their_seeds() {
    let tmp = tempfile::tempdir().unwrap();
    let data_home = tmp.path().join("data");
    let runs = tmp.path().join("runs");
    let serial = "SEEDS-1";
    let rates = "rates_dps = [0, 1, -1, 10, -10]";
    calibrate_plan(
        &data_home,
        &runs.join("other-rates"),
        serial,
        &common::plans::config_with("quick.toml", &[(rates, "rates_dps = [0, 2, -2, 5, -5]")]),
    );
    calibrate_plan(
        &data_home,
        &runs.join("seed1"),
        serial,
        &common::plans::config_with("quick.toml", &[]),
    );
    calibrate_plan(
        &data_home,
        &runs.join("seed2"),
        serial,
        &common::plans::config_with("quick.toml", &[("seed = 1", "seed = 2")]),
    );
    // `rebuild` of the tree into the catalog of `home`, then the history
    let history = |home: &Path, n: usize| {
        ok(&gyrocal(home)
            .args(["catalog", "rebuild"])
            .arg(&runs)
            .output()
            .unwrap());
        let out = gyrocal(home)
            .args(["history", serial, "--include-simulated"])
            .output()
            .unwrap();
        let stdout = ok(&out);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(
            stdout.contains(&format!("repeatability over {n} calibrations")),
            "{stdout}"
        );
        (stdout, stderr)
    };
    // all three: the 5-rate plan with other rates is another plan
    let (stdout, stderr) = history(&data_home, 2);
    assert!(stdout.contains("(1 of other plans left out)"), "{stdout}");
    assert!(stderr.contains("follow 2 plans"), "{stderr}");
    // without it: the two seeds are one plan
    std::fs::remove_dir_all(runs.join("other-rates")).unwrap();
    let (stdout, stderr) = history(&tmp.path().join("fresh"), 2);
    assert!(!stdout.contains("other plans"), "{stdout}");
    assert!(!stderr.contains("plans"), "{stderr}");
}
