//! A multimeter whose replies come late (`--sim-fault dmm:slow@...`), through the binary in
//! virtual time (`gyrocal run --simulate`: the real drivers against the simulators), on the
//! 34401A over RS-232 and through a Prologix GPIB controller and on the 34461A over LAN, in
//! stream and memory modes. What an operator sees: a meter that is slow but alive gives a
//! complete run whose every step holds its own readings (no reply taken for another query's),
//! with the slow replies in the manifest; a meter too slow for the widest deadlines fails the
//! run in bounded time with a message that names slow replies (never a power cycle); the
//! table ends at rest in every case.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::path::{Path, PathBuf};

use common::{config, gyrocal, manifest};

const METERS: &[(&str, &str)] = &[
    ("34401A RS-232", ""),
    (
        "34401A Prologix USB",
        "port = \"prologix:/dev/ttyUSB0?addr=22\"\n",
    ),
    (
        "34461A LAN",
        "model = \"34461a\"\nport = \"tcp://192.0.2.10:5025\"\n",
    ),
];

const MODES: &[&str] = &["stream", "memory"];

/// quick.toml with the meter's keys and the acquisition mode.
fn plan(dir: &Path, meter: &str, mode: &str) -> PathBuf {
    let mut text = std::fs::read_to_string(config("quick.toml")).unwrap();
    assert!(text.contains("acquisition = \"auto\""));
    text = text.replace(
        "acquisition = \"auto\"",
        &format!("acquisition = \"{mode}\""),
    );
    if !meter.is_empty() {
        text = text.replace("port = \"/dev/ttyUSB0\"\n", "");
        text = text.replace("[dmm]\n", &format!("[dmm]\n{meter}"));
    }
    let path = dir.join("plan.toml");
    std::fs::write(&path, text).unwrap();
    path
}

struct Outcome {
    code: Option<i32>,
    stderr: String,
    dir: PathBuf,
}

fn run(tmp: &Path, name: &str, meter: &str, mode: &str, faults: &[&str]) -> Outcome {
    let base = tmp.join(name.replace(' ', "_"));
    std::fs::create_dir_all(&base).unwrap();
    let plan = plan(&base, meter, mode);
    let dir = base.join("run");
    // none of the user's files (station, catalog) and no catalog
    let mut cmd = gyrocal();
    cmd.arg("run")
        .arg(&plan)
        .args(["--simulate", "--no-report", "-o"])
        .arg(&dir);
    for f in faults {
        cmd.args(["--sim-fault", f]);
    }
    let out = cmd.output().unwrap();
    Outcome {
        code: out.status.code(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        dir,
    }
}

/// (step, rate, mean volts, n + overloads) of each row of steps.csv; the step 0-based (the
/// file's `step_no` minus one).
fn steps(dir: &Path) -> Vec<(usize, f64, f64, u64)> {
    let mut r = csv::Reader::from_path(dir.join("steps.csv")).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |name: &str| h.iter().position(|c| c == name).unwrap();
    let (s, rate, v, n, o) = (
        col("step_no"),
        col("rate_dps"),
        col("volts"),
        col("n"),
        col("overloads"),
    );
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            let num = |i: usize| rec[i].parse::<f64>().unwrap();
            (
                num(s) as usize - 1,
                num(rate),
                num(v),
                (num(n) + num(o)) as u64,
            )
        })
        .collect()
}

/// Each step's mean is the simulated gyro's output at its rate (quick.toml's truth: bias
/// 8.8 mV, 0.3612 V/(°/s), K2 2e-5; the earth rate and the noise are far below 5 mV): a reply
/// taken for another query's (a `1`, an error entry, another step's readings) is not.
fn each_step_holds_its_own_readings(name: &str, rows: &[(usize, f64, f64, u64)]) {
    for (step, rate, volts, n) in rows {
        assert_eq!(*n, 50, "{name}: step {step} has {n} readings");
        let truth = 0.0088 + 0.3612 * rate + 2e-5 * rate * rate;
        assert!(
            (volts - truth).abs() < 0.005,
            "{name}: step {step} at {rate} °/s: mean {volts} V, the gyro gives {truth} V"
        );
    }
}

/// gyrocal's closing line for the simulated table: `... mode Off, demand +0 °/s, at rest`.
fn table_at_rest(name: &str, stderr: &str) {
    let line = stderr
        .lines()
        .find_map(|l| l.strip_prefix("simulated table at the end: "))
        .unwrap_or_else(|| panic!("{name}: no final table state in:\n{stderr}"));
    assert!(
        line.starts_with("mode Off") && line.ends_with(", at rest"),
        "{name}: {line}"
    );
}

fn each(faults: &'static [&'static str], check: fn(&str, &Outcome)) {
    let tmp = tempfile::tempdir().unwrap();
    let tmp = tmp.path().to_path_buf();
    std::thread::scope(|s| {
        for (meter_name, meter) in METERS {
            for mode in MODES {
                let tmp = tmp.clone();
                s.spawn(move || {
                    let name = format!("{meter_name} {mode}");
                    let o = run(&tmp, &name, meter, mode, faults);
                    check(&name, &o);
                });
            }
        }
    });
}

/// The meter: from reading 60 on every reply comes 2.5 s late. The run completes on
/// every meter and mode; the late reply is thrown away once and the deadlines widen.
#[test]
fn a_meter_whose_replies_come_2_5_s_late_gives_a_complete_run_on_every_meter_and_mode() {
    each(&["dmm:slow@reading60/2.5s"], |name, o| {
        assert_eq!(o.code, Some(0), "{name}:\n{}", o.stderr);
        let m = manifest(&o.dir);
        assert_eq!(m["status"], "complete", "{name}");
        let rows = steps(&o.dir);
        let mut idx: Vec<usize> = rows.iter().map(|r| r.0).collect();
        idx.sort_unstable();
        assert_eq!(idx, [0, 1, 2, 3, 4], "{name}: every step exactly once");
        each_step_holds_its_own_readings(name, &rows);
        let slow: Vec<&serde_json::Value> = m["retries"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| {
                r["instrument"] == "dmm"
                    && r["message"]
                        .as_str()
                        .is_some_and(|t| t.contains("the meter answers slowly"))
            })
            .collect();
        assert!(
            !slow.is_empty(),
            "{name}: the slow replies are in the manifest\n{m}"
        );
        // the deadlines adapted: not one recovery per step
        let dmm_retries = m["retries"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["instrument"] == "dmm")
            .count();
        assert!(dmm_retries <= 2, "{name}: {dmm_retries} meter retries\n{m}");
        table_at_rest(name, &o.stderr);
    });
}

/// Slow, then slower than any deadline the drivers allow (60 s a reply): the run fails
/// (exit 1) in bounded time, the message names the multimeter and its slow replies and
/// never a power cycle, only whole steps are recorded, and the table ends at rest.
#[test]
fn a_meter_too_slow_for_the_widest_deadlines_fails_the_run_naming_slow_replies() {
    each(
        &["dmm:slow@reading60/2.5s", "dmm:slow@reading160/60s"],
        |name, o| {
            assert_eq!(o.code, Some(1), "{name}:\n{}", o.stderr);
            let m = manifest(&o.dir);
            assert_eq!(m["status"], "failed", "{name}");
            let reason = m["reason"].as_str().unwrap_or_default().to_string();
            assert!(reason.contains("multimeter"), "{name}: {reason}");
            assert!(
                reason.contains("the meter answers slowly"),
                "{name}: {reason}"
            );
            assert!(!reason.contains("power cycle"), "{name}: {reason}");
            assert!(
                o.stderr.contains("the meter answers slowly"),
                "{name}:\n{}",
                o.stderr
            );
            let rows = steps(&o.dir);
            assert!(rows.len() < 5, "{name}: {rows:?}");
            each_step_holds_its_own_readings(name, &rows);
            table_at_rest(name, &o.stderr);
        },
    );
}
