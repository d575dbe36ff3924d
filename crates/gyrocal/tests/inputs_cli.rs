//! Inputs that slipped through (issue 22, item 5), each through the binary: one CSV reader for
//! `fit`, `report` and `allan` (bounded lines, a byte-order mark accepted, pipes and devices
//! refused, the file and line named); station and acceptance files opened only when regular
//! files; a calibration dated after today refused; a station without a multimeter or table
//! said at the terminal; a drift plan's rates exactly `[0]`; `--temp-dir` problems exit 2.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{config, gyrocal};

/// Runs `cmd`, failing the test if it has not ended within `secs` (it is killed then): a
/// command that blocks on a named pipe must not hang the suite.
fn output_within(cmd: &mut Command, secs: u64) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if started.elapsed() > Duration::from_secs(secs) {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "still running after {secs} s (blocked?): {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A named pipe at `dir/name` (nobody ever writes to it).
fn fifo(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(name);
    let ok = Command::new("mkfifo").arg(&path).status().unwrap();
    assert!(ok.success(), "mkfifo {}", path.display());
    path
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A sparse file of `len` bytes starting with `head` and then zero bytes: no newline after
/// `head`, whatever its size (a 3 GB "line" costs no disk).
fn huge_line_file(dir: &Path, name: &str, head: &str, len: u64) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, head).unwrap();
    let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    f.set_len(len).unwrap();
    path
}

/// `gyrocal ARGS` under a virtual-memory limit of `mib` MiB (`ulimit -v`): an input read
/// without bound dies there (SIGABRT on a failed allocation) instead of exiting cleanly.
fn gyrocal_limited(mib: u64, args: &[&std::ffi::OsStr]) -> Command {
    let mut c = Command::new("sh");
    c.arg("-c")
        .arg(format!("ulimit -v {} && exec \"$0\" \"$@\"", mib * 1024))
        .arg(env!("CARGO_BIN_EXE_gyrocal"))
        .args(args);
    // the same clean environment as every other run of the binary (tests/common)
    common::remove_users_own(&mut c);
    c.env("GYROCAL_CATALOG", "off");
    c
}

const GB3: u64 = 3 * 1000 * 1000 * 1000;

#[test]
fn allan_refuses_a_3_gb_line_after_a_bounded_read_and_does_not_echo_it() {
    let tmp = tempfile::tempdir().unwrap();
    // no newline at all, and a valid header and row followed by a line without end
    let bare = huge_line_file(tmp.path(), "bare.csv", "", GB3);
    let after = huge_line_file(tmp.path(), "after.csv", "t_s,volts\n0,0.1\n", GB3);
    for (path, line) in [(&bare, 1), (&after, 3)] {
        for streaming in [false, true] {
            let mut args = vec![std::ffi::OsStr::new("allan"), path.as_os_str()];
            if streaming {
                args.push(std::ffi::OsStr::new("--streaming"));
            }
            let started = Instant::now();
            // 512 MiB of address space: the old reader needed 18 GiB for this file
            let o = output_within(&mut gyrocal_limited(512, &args), 60);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{err}");
            assert!(
                err.contains(&format!("{}: line {line}: longer than", path.display())),
                "{err}"
            );
            // the "line" is never echoed: the message is one short line
            assert!(err.len() < 400, "{} bytes: {err}", err.len());
            assert!(started.elapsed() < Duration::from_secs(30));
        }
    }
}

#[test]
fn fit_and_report_refuse_a_3_gb_line_after_a_bounded_read() {
    let tmp = tempfile::tempdir().unwrap();
    let path = huge_line_file(tmp.path(), "steps.csv", "rate_dps,volts\n0,0.01\n", GB3);
    for cmd in ["fit", "report"] {
        let mut args = vec![std::ffi::OsStr::new(cmd), path.as_os_str()];
        let out = tmp.path().join("r.html");
        if cmd == "report" {
            args.extend([std::ffi::OsStr::new("--out"), out.as_os_str()]);
        }
        let o = output_within(&mut gyrocal_limited(512, &args), 60);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{cmd}: {err}");
        assert!(
            err.contains(&format!("{}: line 3: longer than", path.display())),
            "{cmd}: {err}"
        );
        assert!(err.len() < 400, "{cmd}: {err}");
    }
}

/// The paper's data as Excel saves a "CSV UTF-8" file: a byte-order mark first, CRLF lines.
fn excel_csv(dir: &Path) -> PathBuf {
    let mut text = String::from("\u{feff}rate_dps,volts\r\n");
    for (w, v) in [
        (-20.0, -7.2152),
        (-10.0, -3.6032),
        (0.0, 0.0088),
        (10.0, 3.6208),
        (20.0, 7.2328),
    ] {
        text.push_str(&format!("{w},{v}\r\n"));
    }
    let path = dir.join("excel.csv");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn fit_report_and_allan_accept_a_csv_with_a_byte_order_mark() {
    let tmp = tempfile::tempdir().unwrap();
    let path = excel_csv(tmp.path());
    let o = gyrocal()
        .arg("fit")
        .arg(&path)
        .arg("--json")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // one file: the first of `files` (fit --json has one shape for any number of files)
    let doc = serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()["files"][0].take();
    let k = doc["metrics"]["scale_factor"].as_f64().unwrap();
    assert!((k - 0.3612).abs() < 1e-3, "{doc}");

    let out = tmp.path().join("report.html");
    let o = gyrocal()
        .arg("report")
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(out.exists());

    // a record whose first column is the time, with a BOM before it
    let mut rec = String::from("\u{feff}t_s,volts\n");
    for i in 0..400 {
        rec.push_str(&format!(
            "{},{}\n",
            i as f64 * 0.5,
            0.0088 + 1e-4 * ((i * 7919) % 13) as f64
        ));
    }
    let rec_path = tmp.path().join("record.csv");
    std::fs::write(&rec_path, rec).unwrap();
    let o = gyrocal()
        .arg("allan")
        .arg(&rec_path)
        .arg("--json")
        .args(["--warmup-window", "0"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(doc["time_column"], "t_s", "{doc}");
    assert_eq!(doc["tau0_s"], 0.5, "{doc}");
}

#[test]
fn fit_report_and_allan_refuse_pipes_and_devices_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let pipe = fifo(tmp.path(), "data.csv");
    let out = tmp.path().join("r.html");
    for target in [pipe.as_path(), Path::new("/dev/zero")] {
        for cmd in ["fit", "report", "allan"] {
            let mut c = gyrocal();
            c.arg(cmd).arg(target);
            if cmd == "report" {
                c.arg("--out").arg(&out);
            }
            let o = output_within(&mut c, 20);
            let err = stderr(&o);
            assert_eq!(
                o.status.code(),
                Some(2),
                "{cmd} {}: {err}",
                target.display()
            );
            assert!(err.contains(&target.display().to_string()), "{cmd}: {err}");
        }
    }
}

#[test]
fn station_and_acceptance_fifos_are_refused_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let pipe = fifo(tmp.path(), "station.toml");
    for sub in ["run", "check"] {
        let mut c = gyrocal();
        c.arg(sub)
            .arg(config("quick.toml"))
            .arg("--station")
            .arg(&pipe);
        if sub == "run" {
            c.arg("--simulate")
                .arg("--out")
                .arg(tmp.path().join("never"));
        }
        let o = output_within(&mut c, 20);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{sub}: {err}");
        assert!(
            err.contains("station.toml") && err.contains("named pipe"),
            "{sub}: {err}"
        );
    }
    assert!(!tmp.path().join("never").exists());

    // --acceptance: a real run directory, limits from a pipe
    let run = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .arg("--simulate")
        .arg("--out")
        .arg(&run)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let limits = fifo(tmp.path(), "limits.toml");
    let o = output_within(
        gyrocal()
            .arg("report")
            .arg(&run)
            .arg("--acceptance")
            .arg(&limits)
            .arg("--out")
            .arg(tmp.path().join("r.html")),
        20,
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("limits.toml") && err.contains("named pipe"),
        "{err}"
    );
}

const STATION: &str = r#"
id = "bench-9"
lab = "Inertial Lab"
address = "1 Test Road"

[multimeter]
model = "HP 34401A"
asset_id = "DMM-0042"
serial = "3146A12345"
certificate = "CAL-0815"
calibrated = "2025-08-15"
due = "2099-08-15"

[table]
model = "ACUTRONIC AC1120S"
asset_id = "TBL-0007"
serial = "AC-1120-77"
certificate = "CAL-0901"
calibrated = "2025-09-01"
due = "2099-09-01"
"#;

#[test]
fn a_calibration_dated_after_today_is_refused_naming_the_instrument() {
    let tmp = tempfile::tempdir().unwrap();
    let today = jiff::Zoned::now().date();
    let tomorrow = today.tomorrow().unwrap();
    let next_year = today.checked_add(jiff::Span::new().years(1)).unwrap();
    for (date, section, asset) in [
        (tomorrow, "multimeter", "DMM-0042"),
        (next_year, "table", "TBL-0007"),
    ] {
        let old = if section == "multimeter" {
            "calibrated = \"2025-08-15\""
        } else {
            "calibrated = \"2025-09-01\""
        };
        let station = tmp.path().join(format!("future-{section}.toml"));
        std::fs::write(
            &station,
            STATION.replace(old, &format!("calibrated = {date}")),
        )
        .unwrap();
        for sub in ["run", "check"] {
            let mut c = gyrocal();
            c.arg(sub)
                .arg(config("quick.toml"))
                .arg("--station")
                .arg(&station);
            let out = tmp.path().join("never");
            if sub == "run" {
                c.arg("--simulate").arg("--out").arg(&out);
            }
            let o = c.output().unwrap();
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{sub}: {err}");
            assert!(
                err.contains(&format!("future-{section}.toml"))
                    && err.contains(&format!("[{section}] calibrated = {date} is after today"))
                    && err.contains(asset),
                "{sub}: {err}"
            );
            if sub == "run" {
                assert!(!out.exists(), "nothing is created when the run is refused");
            }
        }
    }
    // today itself is a valid calibration date
    let station = tmp.path().join("today.toml");
    std::fs::write(
        &station,
        STATION.replace(
            "calibrated = \"2025-08-15\"",
            &format!("calibrated = {today}"),
        ),
    )
    .unwrap();
    let o = gyrocal()
        .arg("check")
        .arg(config("quick.toml"))
        .arg("--station")
        .arg(&station)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn a_station_without_a_multimeter_or_table_is_said_at_the_terminal() {
    let tmp = tempfile::tempdir().unwrap();
    let table_start = STATION.find("[table]").unwrap();
    let meter_start = STATION.find("[multimeter]").unwrap();
    let no_meter = format!("{}{}", &STATION[..meter_start], &STATION[table_start..]);
    let no_table = &STATION[..table_start];
    let a = tmp.path().join("no-meter.toml");
    std::fs::write(&a, no_meter).unwrap();
    let b = tmp.path().join("no-table.toml");
    std::fs::write(&b, no_table).unwrap();

    // check: a warning line each, exit 0
    for (station, section) in [(&a, "multimeter"), (&b, "table")] {
        let o = gyrocal()
            .arg("check")
            .arg(config("quick.toml"))
            .arg("--station")
            .arg(station)
            .output()
            .unwrap();
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(0), "{err}");
        let warning = format!(
            "gyrocal: warning: station bench-9 ({}) has no [{section}] section",
            station.display()
        );
        assert!(err.contains(&warning), "{err}");
    }
    // a complete station: no such warning
    let full = tmp.path().join("full.toml");
    std::fs::write(&full, STATION).unwrap();
    let o = gyrocal()
        .arg("check")
        .arg(config("quick.toml"))
        .arg("--station")
        .arg(&full)
        .output()
        .unwrap();
    assert!(!stderr(&o).contains("section"), "{}", stderr(&o));

    // run: said before the instruments move; the run goes on
    let out = tmp.path().join("run");
    let o = gyrocal()
        .arg("run")
        .arg(config("quick.toml"))
        .args(["--simulate", "--station"])
        .arg(&a)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert!(
        err.contains("gyrocal: warning: station bench-9")
            && err.contains("has no [multimeter] section"),
        "{err}"
    );
    // and the certificate says it in the instruments table
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let table = common::between(&html, "id=\"instruments-table\"", "</table>");
    let meter_row = common::between(table, "<tr><td>Multimeter</td>", "</tr>");
    assert!(meter_row.contains("not in the station file"), "{meter_row}");
}

#[test]
fn a_drift_plan_with_more_than_one_rate_is_refused_with_file_line_and_key() {
    let tmp = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(config("drift.toml")).unwrap();
    let line = text
        .lines()
        .position(|l| l.starts_with("rates_dps = [0]"))
        .unwrap()
        + 1;
    let plan = tmp.path().join("drift-twice.toml");
    std::fs::write(&plan, text.replace("rates_dps = [0]", "rates_dps = [0, 0]")).unwrap();
    let o = gyrocal().arg("check").arg(&plan).output().unwrap();
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!("drift-twice.toml:{line}:")) && err.contains("rates_dps"),
        "{err}"
    );
    assert!(err.contains("exactly rates_dps = [0]"), "{err}");
    // the shipped plan is still accepted
    let o = gyrocal()
        .arg("check")
        .arg(config("drift.toml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn allan_temp_dir_problems_are_bad_input_naming_the_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rec = String::from("t_s,volts\n");
    for i in 0..200 {
        rec.push_str(&format!("{i},{}\n", 0.01 + 1e-4 * ((i * 31) % 7) as f64));
    }
    let path = tmp.path().join("rec.csv");
    std::fs::write(&path, rec).unwrap();
    let not_a_dir = tmp.path().join("plain-file");
    std::fs::write(&not_a_dir, "x").unwrap();
    let missing = tmp.path().join("nonexistent");
    for (dir, says) in [
        (missing.as_path(), "no such directory"),
        (not_a_dir.as_path(), "not a directory"),
    ] {
        for streaming in [false, true] {
            let mut c = gyrocal();
            c.arg("allan").arg(&path).arg("--temp-dir").arg(dir);
            if streaming {
                c.arg("--streaming");
            }
            let o = c.output().unwrap();
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{err}");
            assert!(
                err.contains(&dir.display().to_string()) && err.contains(says),
                "{err}"
            );
        }
    }
    // a good one works, on both paths
    for streaming in [false, true] {
        let mut c = gyrocal();
        c.arg("allan").arg(&path).arg("--temp-dir").arg(tmp.path());
        if streaming {
            c.arg("--streaming");
        }
        let o = c.output().unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    }
}
