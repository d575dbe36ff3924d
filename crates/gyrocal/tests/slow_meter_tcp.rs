//! The meter as a process: `gyrocal sim --dmm 34461a --fault dmm:slow@...` serves a
//! 34461A on a real TCP socket whose every reply comes 2.5 s late (real seconds: the delay is
//! in sim seconds, scaled by `--time-scale`), and `gyrocal run` runs a small plan against it
//! and the simulated table on a pseudo-terminal, in memory mode (where the run used to
//! reconnect and reconfigure without end) and in stream mode. The run completes, every step
//! holds its own readings, the manifest says the meter answers slowly, the simulator saw late
//! replies and few reconnects, and the table ends at rest.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

mod common;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Lines};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Stdio};

use common::{gyrocal, plans};

/// Kills the simulator if the test fails before it is stopped.
struct Sim {
    child: Child,
    lines: Lines<BufReader<ChildStdout>>,
}

impl Sim {
    fn start(time_scale: f64, faults: &[&str]) -> (Sim, serde_json::Value) {
        let mut cmd = gyrocal();
        cmd.args(["sim", "--dmm", "34461a", "--seed", "3", "--time-scale"])
            .arg(time_scale.to_string());
        for f in faults {
            cmd.args(["--fault", f]);
        }
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let hello: serde_json::Value =
            serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
        (Sim { child, lines }, hello)
    }

    /// SIGTERM, and the simulator's final state line.
    fn stop(mut self) -> serde_json::Value {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(i32::try_from(self.child.id()).unwrap()),
            nix::sys::signal::Signal::SIGTERM,
        );
        let last = self.lines.next().unwrap().unwrap();
        let _ = self.child.wait();
        serde_json::from_str(&last).unwrap()
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `configs/keysight-34461a.toml` on the simulator's ports, shortened (3 rates of 50
/// readings, no settling) and in acquisition `mode`: the kit's exact-text replacements, each
/// of which fails the test if the shipped plan no longer has its text.
fn plan(dir: &Path, dmm: &str, table: &str, mode: &str) -> PathBuf {
    let text = plans::config_with(
        "keysight-34461a.toml",
        &[
            (
                "rates_dps = [0, 0.1, -0.1, 0.3, -0.3, 0.7, -0.7, 1, -1, 3, -3, 7, -7, 10, -10, 15, -15, 20, -20]",
                "rates_dps = [0, 5, -5]",
            ),
            ("samples_per_rate = 500", "samples_per_rate = 50"),
            ("settle_s = 10", "settle_s = 0"),
            (
                "port = \"tcp://192.0.2.10:5025\"",
                &format!("port = \"{dmm}\""),
            ),
            ("port = \"/dev/ttyUSB1\"", &format!("port = \"{table}\"")),
            ("stability_window_s = 2", "stability_window_s = 0.2"),
            ("acceleration_dps2 = 10", "acceleration_dps2 = 100"),
            (
                "acquisition = \"auto\"",
                &format!("acquisition = \"{mode}\""),
            ),
        ],
    );
    plans::write(dir, &format!("{mode}.toml"), &text)
}

fn case(mode: &'static str) {
    let tmp = tempfile::tempdir().unwrap();
    // time scale 5: 12.5 sim seconds are 2.5 real seconds, the delay
    let (sim, hello) = Sim::start(5.0, &["dmm:slow@reading20/12.5s"]);
    let dmm = hello["dmm"].as_str().unwrap();
    let table = hello["table"].as_str().unwrap();
    assert!(dmm.starts_with("tcp://127.0.0.1:"), "{hello}");
    let plan = plan(tmp.path(), dmm, table, mode);
    let dir = tmp.path().join("run");
    let out = gyrocal()
        .args(["run", "--no-report", "--out"])
        .arg(&dir)
        .arg(&plan)
        .output()
        .unwrap();
    let end = sim.stop();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{mode}:\n{err}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["status"], "complete", "{mode}: {m}");
    assert!(
        m["retries"].as_array().unwrap().iter().any(|r| r["message"]
            .as_str()
            .is_some_and(|t| t.contains("the meter answers slowly"))),
        "{mode}: {m}"
    );
    // every step holds its own readings: the mean is the gyro's output at its rate
    let truth = &hello["truth"];
    let k0 = truth["k0"].as_f64().unwrap();
    let mut r = csv::Reader::from_path(dir.join("steps.csv")).unwrap();
    let rows: Vec<BTreeMap<String, String>> = r.deserialize().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 3, "{mode}");
    for row in &rows {
        let rate: f64 = row["rate_dps"].parse().unwrap();
        let volts: f64 = row["volts"].parse().unwrap();
        let k1 = if rate >= 0.0 {
            truth["k1_pos"].as_f64().unwrap()
        } else {
            truth["k1_neg"].as_f64().unwrap()
        };
        let want = k0 + k1 * rate + truth["k2"].as_f64().unwrap() * rate * rate;
        assert!(
            (volts - want).abs() < 0.01,
            "{mode}: {rate} °/s: mean {volts} V, the gyro gives about {want} V"
        );
        assert_eq!(row["n"], "50", "{mode}: {row:?}");
    }
    // the simulator: late replies sent, a handful of reconnects (not one per exchange), and
    // the table at rest
    let late = end["dmm"]["late_replies"].as_u64().unwrap();
    assert!(late > 5, "{mode}: {end}");
    let clears = end["dmm"]["device_clears"].as_u64().unwrap();
    assert!(clears <= 6, "{mode}: {clears} reconnects: {end}");
    assert_eq!(end["table"]["stopped"], true, "{mode}: {end}");
    assert_eq!(end["table"]["mode"], "OFF", "{mode}: {end}");
}

#[test]
fn a_34461a_with_2_5_s_late_replies_over_tcp_completes_in_memory_mode() {
    case("memory");
}

#[test]
fn a_34461a_with_2_5_s_late_replies_over_tcp_completes_in_stream_mode() {
    case("stream");
}
