//! `gyrocal sim` as a process: its JSON lines, the real drivers over its pseudo-terminals (and
//! TCP), fault specs firing where they say, reconnects, and a clean exit on SIGINT. Real time
//! with a time scale (pseudo-terminals and virtual time do not mix).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::io::{BufRead, BufReader};
use std::process::{Child, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use gyrocal_acl::{AclConfig, AclTable};
use gyrocal_hp34401a::{AutoZero, DcvConfig, DriverOptions, Hp34401a, Strategy};
use gyrocal_link::LinkOptions;
use gyrocal_table::{Limits, RateTable, SettleCriteria};
use serde_json::Value;

/// A running `gyrocal sim`; killed on drop if still running.
struct Sim {
    child: Child,
    lines: mpsc::Receiver<String>,
    info: Value,
}

impl Sim {
    fn start(extra: &[&str]) -> Sim {
        let mut child = common::gyrocal()
            .args(["sim", "--time-scale", "50", "--seed", "7"])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let first = lines
            .recv_timeout(Duration::from_secs(10))
            .expect("the JSON line with the device paths");
        let info: Value = serde_json::from_str(&first).unwrap();
        Sim { child, lines, info }
    }

    fn path(&self, key: &str) -> String {
        self.info[key].as_str().unwrap().to_string()
    }

    /// SIGINT; the exit status and the final-state line; nothing else on stdout.
    fn interrupt(mut self) -> (ExitStatus, Value) {
        let pid = nix::unistd::Pid::from_raw(i32::try_from(self.child.id()).unwrap());
        nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
        let last = self
            .lines
            .recv_timeout(Duration::from_secs(5))
            .expect("the final-state line");
        let status = self.child.wait().unwrap();
        assert!(
            self.lines.recv_timeout(Duration::from_secs(1)).is_err(),
            "nothing after the final line"
        );
        (status, serde_json::from_str(&last).unwrap())
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn dmm_options() -> DriverOptions {
    DriverOptions {
        clear_settle: Duration::from_millis(20),
        ..DriverOptions::default()
    }
}

fn dcv() -> DcvConfig {
    DcvConfig {
        nplc: 1.0,
        autozero: AutoZero::On,
        range: Some(10.0),
        ..DcvConfig::default()
    }
}

fn table_config() -> AclConfig {
    AclConfig {
        limits: Limits {
            max_rate: 30.0,
            max_acceleration: 100.0,
        },
        stop_poll_interval: Duration::from_millis(10),
        ..AclConfig::default()
    }
}

fn settle() -> SettleCriteria {
    SettleCriteria {
        window: Duration::from_millis(150),
        interval: Duration::from_millis(20),
        timeout: Duration::from_secs(5),
        ..SettleCriteria::default()
    }
}

async fn open(path: &str) -> gyrocal_link::Link {
    gyrocal_link::open(path, &LinkOptions::default())
        .await
        .unwrap()
}

/// Noise-free output at table rate `rate` from the truth line.
fn expected_volts(truth: &Value, rate: f64) -> f64 {
    let f = |k: &str| truth[k].as_f64().unwrap();
    let w = rate + f("earth_rate");
    let k1 = if w >= 0.0 { f("k1_pos") } else { f("k1_neg") };
    f("k0") + k1 * w + f("k2") * w * w + f("k3") * w * w * w
}

#[tokio::test]
async fn sim_serves_both_instruments_to_the_real_drivers_and_stops_on_sigint() {
    let sim = Sim::start(&[]);
    assert!(sim.path("dmm").starts_with("/dev/"), "{}", sim.info);
    assert!(sim.path("table").starts_with("/dev/"), "{}", sim.info);
    assert!(sim.info.get("table_tcp").is_none());
    let truth = sim.info["truth"].clone();

    let mut dmm = Hp34401a::new(open(&sim.path("dmm")).await, dmm_options());
    let id = dmm.connect().await.unwrap().clone();
    assert_eq!(id.model, "34401A");
    dmm.configure(&dcv()).await.unwrap();

    let mut table = AclTable::new(open(&sim.path("table")).await, table_config());
    let tid = table.connect().await.unwrap();
    assert_eq!(tid.manufacturer, "ACUTRONIC");
    table.enable().await.unwrap();
    for rate in [10.0, -10.0] {
        table.set_rate(rate, 100.0).await.unwrap();
        table.wait_at_rate(&settle()).await.unwrap();
        let acq = dmm.acquire(20, Strategy::Stream).await.unwrap();
        assert_eq!(acq.readings.len(), 20);
        assert_eq!(acq.retries, 0);
        let v = acq.volts();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let want = expected_volts(&truth, rate);
        assert!(
            (mean - want).abs() < 5e-3,
            "at {rate}: {mean} V, truth {want} V"
        );
    }
    table.stop().await.unwrap();
    table.wait_stopped(Duration::from_secs(5)).await.unwrap();

    let (status, last) = sim.interrupt();
    assert!(status.success(), "{status:?}");
    assert_eq!(last["exit"], "SIGINT");
    assert_eq!(last["table"]["stopped"], true, "{last}");
    assert_eq!(last["table"]["mode"], "OFF", "{last}");
    assert_eq!(last["table"]["demanded_rate"], 0.0, "{last}");
    assert_eq!(last["table"]["demands_seen"], 2, "{last}");
    assert!(
        last["dmm"]["readings_taken"].as_u64().unwrap() >= 40,
        "{last}"
    );
    assert_eq!(last["dmm"]["remote"], true, "{last}");
}

#[tokio::test]
async fn sim_garbled_reading_is_retried_and_overloads_follow_a_demand() {
    let sim = Sim::start(&[
        "--fault",
        "dmm:garble@reading5",
        "--fault",
        "dmm:overload@demand1x3",
    ]);
    assert_eq!(
        sim.info["faults"],
        serde_json::json!(["dmm:garble@reading5", "dmm:overload@demand1x3"])
    );
    let mut dmm = Hp34401a::new(open(&sim.path("dmm")).await, dmm_options());
    dmm.connect().await.unwrap();
    dmm.configure(&dcv()).await.unwrap();
    // reading 5 is garbled: the driver's stream fails on it, it clears the meter and retries
    let acq = dmm.acquire(10, Strategy::Stream).await.unwrap();
    assert_eq!(acq.retries, 1);
    assert_eq!(acq.readings.len(), 10);
    assert_eq!(acq.overloads(), 0);

    // the first rate demand arms three overload readings (a supervisor watches the table)
    let mut table = AclTable::new(open(&sim.path("table")).await, table_config());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    table.set_rate(5.0, 100.0).await.unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    let acq = dmm.acquire(10, Strategy::Stream).await.unwrap();
    assert_eq!(acq.overloads(), 3, "{:?}", acq.readings);
    table.stop().await.unwrap();
    table.wait_stopped(Duration::from_secs(5)).await.unwrap();

    let (status, last) = sim.interrupt();
    assert!(status.success());
    assert_eq!(last["table"]["stopped"], true, "{last}");
    assert_eq!(
        last["faults"],
        serde_json::json!([
            {"spec": "dmm:garble@reading5", "fired": true},
            {"spec": "dmm:overload@demand1x3", "fired": true},
        ])
    );
}

#[tokio::test]
async fn sim_table_trip_at_a_demand_reaches_the_driver_and_the_table_ends_stopped() {
    let sim = Sim::start(&["--fault", "table:trip@demand2"]);
    let mut table = AclTable::new(open(&sim.path("table")).await, table_config());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    table.set_rate(5.0, 100.0).await.unwrap();
    table.wait_at_rate(&settle()).await.unwrap();
    table.set_rate(20.0, 10.0).await.unwrap();
    let err = table.wait_at_rate(&settle()).await.unwrap_err();
    assert!(err.to_string().contains("Rate trip"), "{err}");
    let (status, last) = sim.interrupt();
    assert!(status.success());
    assert_eq!(last["table"]["stopped"], true, "{last}");
    assert_eq!(last["table"]["mode"], "OFF", "{last}");
    assert!(
        last["table"]["fault"]
            .as_str()
            .unwrap()
            .contains("Rate trip"),
        "{last}"
    );
}

#[tokio::test]
async fn sim_silent_table_is_left_turning_and_the_final_line_says_so() {
    let sim = Sim::start(&["--fault", "table:silent@demand2"]);
    let mut table = AclTable::new(open(&sim.path("table")).await, table_config());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    table.set_rate(5.0, 100.0).await.unwrap();
    table.wait_at_rate(&settle()).await.unwrap();
    assert!(table.set_rate(10.0, 100.0).await.is_err());
    let (status, last) = sim.interrupt();
    assert!(status.success());
    assert_eq!(last["table"]["silent"], true, "{last}");
    assert_eq!(last["table"]["stopped"], false, "{last}");
    assert_eq!(last["table"]["demanded_rate"], 5.0, "{last}");
}

#[tokio::test]
async fn sim_meter_disconnect_ends_the_meter_for_good() {
    let sim = Sim::start(&["--fault", "dmm:disconnect@reading3"]);
    let mut dmm = Hp34401a::new(open(&sim.path("dmm")).await, dmm_options());
    dmm.connect().await.unwrap();
    dmm.configure(&dcv()).await.unwrap();
    let err = dmm.acquire(10, Strategy::Stream).await.unwrap_err();
    assert!(
        !err.is_retryable() || err.to_string().contains("gave up"),
        "{err}"
    );
    let (status, last) = sim.interrupt();
    assert!(status.success());
    assert_eq!(last["dmm"]["stopped"], true, "{last}");
    assert_eq!(last["dmm"]["readings_taken"], 2, "{last}");
    assert_eq!(last["faults"][0]["fired"], true, "{last}");
}

#[tokio::test]
async fn sim_clients_can_close_and_reopen_the_ports_and_use_tcp() {
    let sim = Sim::start(&["--table-tcp", "0"]);
    let tcp = sim.path("table_tcp");
    assert!(tcp.starts_with("tcp://127.0.0.1:"), "{tcp}");

    // first session: meter and table over their pseudo-terminals, table left turning
    {
        let mut dmm = Hp34401a::new(open(&sim.path("dmm")).await, dmm_options());
        dmm.connect().await.unwrap();
        dmm.configure(&dcv()).await.unwrap();
        assert_eq!(
            dmm.acquire(5, Strategy::Stream)
                .await
                .unwrap()
                .readings
                .len(),
            5
        );
        let mut table = AclTable::new(open(&sim.path("table")).await, table_config());
        table.connect().await.unwrap();
        table.enable().await.unwrap();
        table.set_rate(3.0, 100.0).await.unwrap();
        table.wait_at_rate(&settle()).await.unwrap();
        // both links dropped here, as a crashed run drops them
    }
    // second session on the same paths: the simulators kept running and their state
    let mut dmm = Hp34401a::new(open(&sim.path("dmm")).await, dmm_options());
    dmm.connect().await.unwrap();
    dmm.configure(&dcv()).await.unwrap();
    assert_eq!(
        dmm.acquire(5, Strategy::Memory)
            .await
            .unwrap()
            .readings
            .len(),
        5
    );
    let mut table = AclTable::new(open(&sim.path("table")).await, table_config());
    table.connect().await.unwrap();
    // and the same table over TCP
    let mut over_tcp = AclTable::new(open(&tcp).await, table_config());
    over_tcp.connect().await.unwrap();
    over_tcp.stop().await.unwrap();
    over_tcp.wait_stopped(Duration::from_secs(5)).await.unwrap();

    let (status, last) = sim.interrupt();
    assert!(status.success());
    assert_eq!(last["table"]["stopped"], true, "{last}");
    assert_eq!(last["table"]["demands_seen"], 1, "{last}");
    assert!(
        last["dmm"]["readings_taken"].as_u64().unwrap() >= 10,
        "{last}"
    );
}

#[test]
fn sim_bad_fault_spec_or_config_exits_2_naming_it() {
    for (args, needle) in [
        (
            vec!["sim", "--fault", "dmm:melt@reading3"],
            "dmm:melt@reading3",
        ),
        (
            vec!["sim", "--fault", "table:trip@step3"],
            "table:trip@step3",
        ),
        (vec!["sim", "--time-scale", "0"], "time scale"),
        (
            vec!["sim", "--config", "/nonexistent/bench.toml"],
            "/nonexistent/bench.toml",
        ),
    ] {
        let out = common::gyrocal().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bench.toml");
    std::fs::write(&bad, "seed = 3\n[gyro]\nk9 = 1\n").unwrap();
    let out = common::gyrocal()
        .args(["sim", "--config"])
        .arg(&bad)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bench.toml") && err.contains("k9"), "{err}");
}

#[test]
fn sim_takes_a_bench_toml_or_a_plan() {
    let dir = tempfile::tempdir().unwrap();
    let bench = dir.path().join("bench.toml");
    std::fs::write(&bench, "seed = 3\n[gyro]\nk1 = 0.25\nk1_neg = 0.24\n").unwrap();
    let sim = Sim::start(&["--config", bench.to_str().unwrap()]);
    assert_eq!(sim.info["seed"], 7, "--seed overrides the file");
    assert_eq!(sim.info["truth"]["k1_pos"], 0.25);
    assert_eq!(sim.info["truth"]["k1_neg"], 0.24);
    drop(sim);

    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/../../configs/quick.toml");
    let sim = Sim::start(&["--config", plan]);
    let k = sim.info["truth"]["k1_pos"].as_f64().unwrap();
    assert!((k - 0.3612).abs() < 1e-3, "{}", sim.info);
    assert_eq!(sim.info["truth"]["k2"], 2e-5);
}

/// The same driver session against a real bench: `GYROCAL_DMM_PORT` and `GYROCAL_TABLE_PORT`
/// (serial paths at 9600 8N2, or `tcp://host:port`), optionally `GYROCAL_TEST_RATE` (deg/s,
/// default 1). Ignored by default; see TESTING.md. The table turns slowly (1 deg/s², at most
/// 5 deg/s) and is stopped whatever happens.
#[tokio::test]
#[ignore = "needs real instruments: set GYROCAL_DMM_PORT and GYROCAL_TABLE_PORT"]
async fn real_bench_identify_spin_read_stop() {
    let dmm_port = std::env::var("GYROCAL_DMM_PORT").expect("GYROCAL_DMM_PORT");
    let table_port = std::env::var("GYROCAL_TABLE_PORT").expect("GYROCAL_TABLE_PORT");
    let rate: f64 = std::env::var("GYROCAL_TEST_RATE")
        .ok()
        .map_or(1.0, |r| r.parse().expect("GYROCAL_TEST_RATE in deg/s"));
    assert!(
        rate.abs() <= 5.0,
        "GYROCAL_TEST_RATE is capped at 5 deg/s here"
    );

    let mut dmm = Hp34401a::new(open(&dmm_port).await, DriverOptions::default());
    let id = dmm.connect().await.unwrap().clone();
    assert_eq!(id.model, "34401A");
    dmm.configure(&dcv()).await.unwrap();

    let mut table = AclTable::new(open(&table_port).await, AclConfig::default());
    table.connect().await.unwrap();
    let guard = table.stop_handle().guard();
    let outcome = async {
        table.enable().await?;
        table.set_rate(rate, 1.0).await?;
        table.wait_at_rate(&SettleCriteria::default()).await?;
        Ok::<_, gyrocal_table::TableError>(())
    }
    .await;
    let acq = dmm.acquire(20, Strategy::Stream).await;
    let stopped = table.stop().await;
    let waited = table.wait_stopped(Duration::from_secs(60)).await;
    guard.disarm();
    outcome.unwrap();
    stopped.unwrap();
    waited.unwrap();
    let acq = acq.unwrap();
    assert_eq!(acq.readings.len(), 20);
    assert!(acq.volts().iter().all(|v| v.is_finite()));
}
