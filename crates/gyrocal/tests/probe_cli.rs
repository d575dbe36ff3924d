//! The operator's checks at the instruments (issue 25, item 6), through the binary against
//! `gyrocal sim` on pseudo-terminals: ports given the wrong way round are said as swapped
//! (both probed, both named, a non-zero exit, nothing created and nothing moved), by
//! `gyrocal check --probe` and by `gyrocal run`; and the station file's serials are compared
//! with the serials the instruments report (a mismatch is a warning and a recorded deviation
//! the certificate shows; a match is no warning; a meter that reports no serial is "not
//! compared").
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Output, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use common::sim::Sim;
use serde_json::Value;

/// A small plan (five steps, fast settings) for `dialect`; its ports are placeholders that the
/// command line overrides.
fn write_plan(dir: &Path, dialect: &str) -> PathBuf {
    let text = format!(
        r#"[plan]
name = "probe checks"
rates_dps = [0, 2, -2, 5, -5]
samples_per_rate = 30
settle_s = 0.2
repeat = 1
whole_revolutions = 0

[table]
dialect = "{dialect}"
port = "/dev/ttyUSB1"
baud = 9600
max_rate_dps = 10
acceleration_dps2 = 20
rate_tolerance_dps = 0.01
stability_window_s = 0.2
at_rate_timeout_s = 10

[dmm]
port = "/dev/ttyUSB0"
baud = 9600
framing = "8N2"
range_v = 10
nplc = 1
autozero = true
line_hz = 50
acquisition = "stream"

[simulation]
seed = 3
scale_factor = 0.3612
bias = 0.0088
noise_v = 0.002
rate_noise_dps = 0.0002
"#
    );
    let path = dir.join(format!("plan-{dialect}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// `gyrocal sim --config CONFIG` (a plan, or a bench TOML), sped up 30 times.
fn start_sim(config: &Path) -> Sim {
    Sim::start(&[
        &"--config",
        &config,
        &"--time-scale",
        &"30",
        &"--seed",
        &"11",
    ])
}

/// `gyrocal check PLAN --probe --dmm-port DMM --table-port TABLE` plus `extra`.
fn check_probe(plan: &Path, dmm: &str, table: &str, extra: &[&str]) -> Output {
    common::gyrocal()
        .arg("check")
        .arg(plan)
        .args(["--probe", "--dmm-port", dmm, "--table-port", table])
        .args(extra)
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// What the swapped-ports diagnosis must say, whatever the command: both ports by the flag
/// that named them, both instruments by what they answered, the thing to do, and no cable or
/// baud advice (an instrument did answer on each port).
fn assert_said_swapped(stderr: &str, sim: &Sim, table_identity: &str) {
    assert!(
        stderr.contains(&format!(
            "the ports look swapped: the multimeter answered on --table-port {} and the rate \
             table on --dmm-port {}; swap them",
            sim.dmm(),
            sim.table()
        )),
        "{stderr}"
    );
    // both probed: each instrument is quoted from its own answer
    assert!(
        stderr.contains("HEWLETT-PACKARD,34401A,SIM0001"),
        "{stderr}"
    );
    assert!(stderr.contains(table_identity), "{stderr}");
    assert!(!stderr.contains("did not answer"), "{stderr}");
    assert!(
        !stderr.contains("baud") && !stderr.contains("null-modem"),
        "no cable advice when both instruments answered: {stderr}"
    );
}

#[test]
fn check_probe_says_swapped_ports_probes_both_and_fails() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    let sim = start_sim(&plan);

    // the ports the right way round still pass
    let out = check_probe(&plan, sim.dmm(), sim.table(), &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("probe: rate table ACUTRONIC,ACUTROL3000,SIM0001"),
        "{}",
        text(&out.stdout)
    );

    // swapped
    let out = check_probe(&plan, sim.table(), sim.dmm(), &[]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_said_swapped(&stderr, &sim, "ACUTRONIC,ACUTROL3000,SIM0001");

    // the same in the --json document, for scripts
    let out = check_probe(&plan, sim.table(), sim.dmm(), &["--json"]);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    let probe = &doc["probe"];
    assert_eq!(probe["answered"], false, "{probe}");
    assert_eq!(probe["swapped"], true, "{probe}");
    assert_eq!(probe["ports"]["dmm"]["answered"], "table", "{probe}");
    assert_eq!(probe["ports"]["dmm"]["port"], sim.table(), "{probe}");
    assert_eq!(probe["ports"]["table"]["answered"], "multimeter", "{probe}");
    assert!(
        probe["diagnosis"]
            .as_str()
            .unwrap()
            .starts_with("the ports look swapped"),
        "{probe}"
    );

    // nothing moved
    let last = sim.finish();
    assert_eq!(last["table"]["demands_seen"], 0, "{last}");
}

#[test]
fn check_probe_says_swapped_ports_with_an_aerosmith_table() {
    // an Ideal Aerosmith controller has no *IDN?: its prompt identifies it
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "aerosmith");
    let sim = start_sim(&plan);
    let out = check_probe(&plan, sim.dmm(), sim.table(), &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));

    let out = check_probe(&plan, sim.table(), sim.dmm(), &[]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_said_swapped(&stderr, &sim, "Aerosmith-style prompt");
    let last = sim.finish();
    assert_eq!(last["table"]["demands_seen"], 0, "{last}");
}

#[test]
fn a_table_on_the_meters_port_is_said_and_the_silent_table_port_gets_its_advice() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    let sim = start_sim(&plan);
    // a table port where nothing answers (a pseudo-terminal nobody serves)
    let pty = nix::pty::openpty(None, None).unwrap();
    let silent = nix::unistd::ttyname(&pty.slave).unwrap();
    let silent = silent.to_str().unwrap();
    let out = check_probe(&plan, sim.table(), silent, &[]);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "a rate table answered on the multimeter's port (--dmm-port {}), not the multimeter",
            sim.table()
        )),
        "{stderr}"
    );
    // the other port was probed too, and gets the advice for a silent link
    assert!(
        stderr.contains(&format!("the rate table at {silent} did not answer")),
        "{stderr}"
    );
    assert!(stderr.contains("set to 9600 baud"), "{stderr}");
    drop(pty);
}

#[test]
fn run_with_swapped_ports_says_so_creates_nothing_and_moves_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    let sim = start_sim(&plan);
    let dir = tmp.path().join("run");
    let out = common::gyrocal()
        .arg("run")
        .arg(&plan)
        .args(["--dmm-port", sim.table(), "--table-port", sim.dmm()])
        .args(["--no-report", "--out", dir.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_said_swapped(&stderr, &sim, "ACUTRONIC,ACUTROL3000,SIM0001");
    assert!(!dir.exists(), "nothing created on disk: {stderr}");
    // the table never got a demand and is at rest
    let last = sim.finish();
    assert_eq!(last["table"]["demands_seen"], 0, "{last}");
    assert_eq!(last["table"]["stopped"], true, "{last}");
}

/// `gyrocal run` on the simulator's ports with `station`; the run directory.
fn run_with_station(tmp: &Path, station: &str, sim: &Sim, plan: &Path) -> (Output, PathBuf) {
    let station_path = tmp.join("station.toml");
    std::fs::write(&station_path, station).unwrap();
    let dir = tmp.join("run");
    let out = common::gyrocal()
        .arg("run")
        .arg(plan)
        .args(["--dmm-port", sim.dmm(), "--table-port", sim.table()])
        .arg("--station")
        .arg(&station_path)
        .args(["--out", dir.to_str().unwrap()])
        .output()
        .unwrap();
    (out, dir)
}

#[test]
fn a_station_with_another_meter_serial_warns_and_records_a_deviation_the_certificate_shows() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    let sim = start_sim(&plan);
    // the station's meter is 3146A12345; the simulated meter reports SIM0001 (its table too)
    let station = common::stations::bench_2("").replace("AC-1120-77", "SIM0001");
    let (out, dir) = run_with_station(tmp.path(), &station, &sim, &plan);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "the run goes on: {stderr}");
    let warning = stderr
        .lines()
        .find(|l| l.starts_with("gyrocal: warning: the multimeter DMM-0042"))
        .unwrap_or_else(|| panic!("no serial warning: {stderr}"));
    assert!(
        warning.contains("says serial 3146A12345")
            && warning.contains("reports serial SIM0001")
            && warning.contains("recorded as a deviation"),
        "{warning}"
    );
    // the table's serial matches: said, not warned
    assert!(
        stderr.contains("station: the rate table's serial SIM0001 matches station bench-2"),
        "{stderr}"
    );
    assert!(!stderr.contains("warning: the rate table"), "{stderr}");

    let m = common::manifest(&dir);
    let deviations = m["deviations"].as_array().unwrap();
    let serial: Vec<&Value> = deviations
        .iter()
        .filter(|d| d["kind"] == "instrument-serial-mismatch")
        .collect();
    assert_eq!(serial.len(), 1, "{deviations:?}");
    let t = serial[0]["text"].as_str().unwrap();
    assert!(t.contains("3146A12345") && t.contains("SIM0001"), "{t}");

    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    let list = common::between(&html, "id=\"deviations-list\"", "</ul>");
    assert!(
        list.contains("says serial 3146A12345") && list.contains("reports serial SIM0001"),
        "{list}"
    );
    let last = sim.finish();
    assert_eq!(last["table"]["stopped"], true, "{last}");
}

#[test]
fn a_station_matching_the_instruments_gives_no_warning_and_no_deviation() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    let sim = start_sim(&plan);
    let station = common::stations::bench_2("")
        .replace("3146A12345", "SIM0001")
        .replace("AC-1120-77", "sim0001");
    let (out, dir) = run_with_station(tmp.path(), &station, &sim, &plan);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        !stderr
            .lines()
            .any(|l| l.starts_with("gyrocal: warning:") && l.contains("serial")),
        "no warning: {stderr}"
    );
    // serials compared without regard to case
    assert!(
        stderr.contains("station: the multimeter's serial SIM0001 matches station bench-2")
            && stderr.contains("station: the rate table's serial SIM0001 matches"),
        "{stderr}"
    );
    let m = common::manifest(&dir);
    assert!(
        m["deviations"]
            .as_array()
            .is_none_or(|d| d.iter().all(|d| d["kind"] != "instrument-serial-mismatch")),
        "{m}"
    );
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(!html.contains("reports serial"), "no serial deviation");
    drop(sim);
}

#[test]
fn check_probe_compares_serials_and_a_meter_reporting_none_is_not_compared() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    // a bench whose meter answers as a real 34401A does: 0 in its serial field
    let bench = tmp.path().join("bench.toml");
    std::fs::write(
        &bench,
        "[dmm]\nidentity = \"HEWLETT-PACKARD,34401A,0,11-5-2\"\n[table]\nidentity = \"ACUTRONIC,ACUTROL3000,AC-1120-99,1.0\"\n",
    )
    .unwrap();
    let sim = start_sim(&bench);
    let station = tmp.path().join("station.toml");
    std::fs::write(&station, common::stations::bench_2("")).unwrap();
    let out = check_probe(
        &plan,
        sim.dmm(),
        sim.table(),
        &["--station", station.to_str().unwrap()],
    );
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "a warning, not a failure: {stderr}");
    assert!(
        stdout.contains("station: the multimeter's serial was not compared: the instrument reports no serial (\"0\""),
        "{stdout}"
    );
    assert!(!stderr.contains("multimeter DMM-0042"), "{stderr}");
    assert!(
        stderr.contains(
            "gyrocal: warning: the rate table TBL-0007: station bench-2 says serial AC-1120-77, \
             but the instrument that answered reports serial AC-1120-99"
        ),
        "{stderr}"
    );
    // the same in --json
    let out = check_probe(
        &plan,
        sim.dmm(),
        sim.table(),
        &["--json", "--station", station.to_str().unwrap()],
    );
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    let serials = doc["probe"]["serials"].as_array().unwrap();
    assert_eq!(serials[0]["role"], "multimeter");
    assert_eq!(serials[0]["result"], "not-compared");
    assert_eq!(serials[1]["result"], "mismatch");
}

#[test]
fn a_resume_on_the_same_mismatching_bench_records_the_deviation_once() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    let sim = start_sim(&plan);
    let station = tmp.path().join("station.toml");
    std::fs::write(&station, common::stations::bench_2("")).unwrap();
    let dir = tmp.path().join("run");
    let run = |args: &[&str]| {
        common::gyrocal()
            .arg("run")
            .args(["--dmm-port", sim.dmm(), "--table-port", sim.table()])
            .arg("--station")
            .arg(&station)
            .arg("--no-report")
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    // the first session, stopped by SIGINT once a step is recorded
    let mut first = run(&[plan.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let stderr = first.stderr.take().unwrap();
    let (tx, lines) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    loop {
        let line = lines
            .recv_timeout(Duration::from_secs(20))
            .expect("a step recorded");
        if line.trim_start().starts_with("step 1 done") {
            break;
        }
    }
    let pid = nix::unistd::Pid::from_raw(i32::try_from(first.id()).unwrap());
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    assert_eq!(first.wait().unwrap().code(), Some(130));
    // resumed on the same instruments: warned again, recorded once
    let second = run(&["--resume", dir.to_str().unwrap()])
        .wait_with_output()
        .unwrap();
    let stderr = text(&second.stderr);
    assert_eq!(second.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("reports serial SIM0001"), "{stderr}");
    let m = common::manifest(&dir);
    assert_eq!(m["status"], "complete", "{m}");
    let kinds: Vec<&Value> = m["deviations"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|d| d["kind"] == "instrument-serial-mismatch")
        .collect();
    // the meter's and the table's (bench-2 names other serials for both), each once
    assert_eq!(kinds.len(), 2, "{m}");
    assert!(
        kinds[0]["text"]
            .as_str()
            .unwrap()
            .contains("multimeter DMM-0042")
    );
    assert!(
        kinds[1]["text"]
            .as_str()
            .unwrap()
            .contains("rate table TBL-0007")
    );
    let last = sim.finish();
    assert_eq!(last["table"]["stopped"], true, "{last}");
}

// --- the chamber of a temperature series -----------------------------------------------------

/// `gyrocal sim` for `configs/series.toml` with a Watlow F4 chamber on its own
/// pseudo-terminal, `faults` armed.
fn start_series_sim(faults: &[&str]) -> Sim {
    let plan = common::config("series.toml");
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> =
        vec![&"--config", &plan, &"--chamber", &"watlow_f4"];
    for f in faults {
        args.push(&"--fault");
        args.push(f);
    }
    Sim::start(&args)
}

/// `gyrocal check configs/series.toml --probe` with every port the simulator's, plus `extra`.
fn check_series_probe(sim: &Sim, extra: &[&str]) -> Output {
    check_probe(
        &common::config("series.toml"),
        sim.dmm(),
        sim.table(),
        &[&["--chamber-port", sim.chamber()], extra].concat(),
    )
}

/// A series plan's chamber is probed with the meter and the table: identified (°C, decimal
/// places, range, the limits in force) and read (air, gyro, setpoint, mode, alarms), in the
/// human text and in --json; the series' line names the --chamber-port probed; nothing moved
/// or changed on either machine.
#[test]
fn check_probe_identifies_and_reads_a_series_chamber_changing_nothing() {
    let sim = start_series_sim(&[]);
    let out = check_series_probe(&sim, &[]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains(&format!(
            "probe: chamber Watlow F4 at {} (°C; input 1 (air) 1 decimals, range -70 .. 180 °C; \
             product on input 2 (1 decimals); setpoint limits -40 .. 85 °C)",
            sim.chamber()
        )),
        "{stdout}"
    );
    let reads = stdout
        .lines()
        .find(|l| l.starts_with("probe: chamber reads air "))
        .unwrap_or_else(|| panic!("no chamber reading: {stdout}"));
    assert!(
        reads.contains("setpoint 23.0 °C, mode constant, no alarm") && reads.contains("gyro 2"),
        "{reads}"
    );
    assert!(
        stdout.contains(&format!("chamber watlow_f4 on {}", sim.chamber())),
        "the series' line names the port probed: {stdout}"
    );
    let out = check_series_probe(&sim, &["--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    let c = &doc["probe"]["chamber"];
    assert_eq!(c["answered"], true, "{c:#}");
    assert_eq!(c["model"], "Watlow F4", "{c:#}");
    assert_eq!(c["port"], sim.chamber(), "{c:#}");
    assert_eq!(c["setpoint_c"], 23.0, "{c:#}");
    assert_eq!(c["mode"], "constant", "{c:#}");
    assert_eq!(c["alarms"], serde_json::json!([]), "{c:#}");
    let air = c["air_c"].as_f64().unwrap();
    assert!((air - 23.0).abs() < 1.0, "room temperature: {c:#}");
    assert!(c["product_c"].as_f64().is_some(), "{c:#}");
    let state = sim.finish();
    assert_eq!(state["table"]["demands_seen"], 0, "{state:#}");
    assert_eq!(state["chamber"]["setpoint_c"], 23.0, "{state:#}");
}

/// A chamber that does not answer: refused, exit 1, the port named as the user gave it, the
/// second look said ("nothing answered there") with what to check on the link; the meter and
/// the table are still probed (no word against them).
#[test]
fn check_probe_refuses_a_silent_chamber_naming_its_port() {
    let sim = start_series_sim(&["chamber:silent@request1"]);
    let out = check_series_probe(&sim, &[]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stderr.contains(&format!(
            "the chamber (watlow_f4) at --chamber-port {} did not answer",
            sim.chamber()
        )) && stderr.contains("the chamber is silent")
            && stderr.contains("nothing answered there: check that the controller is on"),
        "{stderr}"
    );
    assert!(!stdout.contains("probe: chamber"), "{stdout}");
    assert!(
        stdout.contains("probe: multimeter HEWLETT-PACKARD,34401A"),
        "{stdout}"
    );
    let out = check_series_probe(&sim, &["--json"]);
    assert_eq!(out.status.code(), Some(1));
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    let c = &doc["probe"]["chamber"];
    assert_eq!(c["answered"], false, "{c:#}");
    assert_eq!(c["answered_by"], "nothing", "{c:#}");
    let state = sim.finish();
    assert_eq!(state["table"]["demands_seen"], 0, "{state:#}");
}

/// A door alarm latched at the chamber: the probe reads it and shows it, and refuses (exit
/// 1) saying a run would stop at once and the alarm is cleared at the chamber.
#[test]
fn check_probe_shows_a_latched_chamber_alarm_and_fails() {
    let sim = start_series_sim(&["chamber:door@t=0s"]);
    let out = check_series_probe(&sim, &[]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stdout.contains("mode constant, ALARM: door open"),
        "the reading shown: {stdout}"
    );
    assert!(
        stderr.contains(&format!(
            "chamber alarm: door open latched on the chamber (watlow_f4) at --chamber-port {}: \
             a run stops at its first reading of the chamber",
            sim.chamber()
        )) && stderr.contains("cleared at the chamber"),
        "{stderr}"
    );
    let out = check_series_probe(&sim, &["--json"]);
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        doc["probe"]["chamber"]["alarms"],
        serde_json::json!(["door open"]),
        "{doc:#}"
    );
    let state = sim.finish();
    // the probe reads the alarm, never resets it
    assert_eq!(
        state["chamber"]["alarms"],
        serde_json::json!(["door open"]),
        "{state:#}"
    );
}

/// A sweep plan has no chamber: nothing about one is probed or said, and a --chamber-port
/// given to it is a warning that it was not probed.
#[test]
fn check_probe_of_a_sweep_plan_probes_no_chamber() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path(), "acl");
    let sim = start_sim(&plan);
    let out = check_probe(
        &plan,
        sim.dmm(),
        sim.table(),
        &["--chamber-port", "/dev/null"],
    );
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(!stdout.contains("chamber"), "{stdout}");
    assert!(
        stderr.contains("the plan has no [chamber] (it is not a temperature series): --chamber-port is not probed"),
        "{stderr}"
    );
    let out = check_probe(&plan, sim.dmm(), sim.table(), &["--json"]);
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(doc["probe"]["chamber"].is_null(), "{doc:#}");
}

/// The chamber over Modbus TCP (`gyrocal sim --chamber-tcp`): `--chamber-port tcp://HOST:PORT`
/// is probed as `gyrocal run` would reach it, identified and read.
#[test]
fn check_probe_reads_a_chamber_over_modbus_tcp() {
    let plan = common::config("series.toml");
    let sim = Sim::start(&[
        &"--config",
        &plan,
        &"--chamber",
        &"watlow_f4",
        &"--chamber-tcp",
        &"0",
    ]);
    assert!(
        sim.chamber().starts_with("tcp://127.0.0.1:"),
        "{}",
        sim.chamber()
    );
    let out = check_series_probe(&sim, &[]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(
        stdout.contains(&format!(
            "probe: chamber Watlow F4 at {} (°C;",
            sim.chamber()
        )),
        "{stdout}"
    );
    assert!(
        stdout.contains("setpoint 23.0 °C, mode constant, no alarm"),
        "{stdout}"
    );
    let state = sim.finish();
    assert!(
        state["chamber"]["requests_seen"].as_u64().unwrap() > 0,
        "{state:#}"
    );
}

/// Another instrument on the chamber's port (here a second bench's rate table): the chamber
/// does not answer, and the second look says who did, and to give the chamber's own port.
#[test]
fn check_probe_says_who_answered_on_the_chambers_port() {
    let sim = start_series_sim(&[]);
    let other = start_sim(&common::config("series.toml"));
    let out = check_probe(
        &common::config("series.toml"),
        sim.dmm(),
        sim.table(),
        &["--chamber-port", other.table()],
    );
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stderr.contains(&format!(
            "the chamber (watlow_f4) at --chamber-port {} did not answer",
            other.table()
        )) && stderr.contains("a rate table answered (*IDN? \"ACUTRONIC,ACUTROL3000")
            && stderr.contains("there: give the chamber's own port"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("check that the controller is on"),
        "{stderr}"
    );
    let state = other.finish();
    assert_eq!(state["table"]["demands_seen"], 0, "{state:#}");
}

/// With a station file, the chamber's controller is compared with the station's `[chamber]`
/// record as `gyrocal run` compares it: another model is a warning before the series starts
/// (its certificate would name another chamber's calibration), the same model is said.
#[test]
fn check_probe_compares_the_chamber_with_the_stations_record() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = start_series_sim(&[]);
    let record = |model: &str| {
        let path = tmp.path().join(format!("station-{}.toml", model.len()));
        let chamber = format!(
            "[chamber]\nmodel = \"{model}\"\nasset_id = \"TC-03\"\nserial = \"S-1\"\n\
             certificate = \"C-3\"\ncalibrated = \"2026-01-01\"\ndue = \"2099-01-01\"\n"
        );
        std::fs::write(
            &path,
            format!("{}\n{chamber}", common::stations::bench_2("")),
        )
        .unwrap();
        path
    };
    let other = record("Espec SH-641");
    let out = check_series_probe(&sim, &["--station", other.to_str().unwrap()]);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "a warning, not a failure: {stderr}");
    assert!(
        stderr.contains(
            "gyrocal: warning: the thermal chamber TC-03: station bench-2 names a Espec SH-641, \
             but the controller that answered is a Watlow F4"
        ),
        "{stderr}"
    );
    let same = record("Watlow F4");
    let out = check_series_probe(&sim, &["--station", same.to_str().unwrap()]);
    let (stdout2, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("thermal chamber TC-03"), "{stderr}");
    assert!(
        stdout2.contains(
            "station: the thermal chamber's controller (Watlow F4) is the one station bench-2 names"
        ),
        "{stdout2}\n(the first: {stdout})"
    );
    let state = sim.finish();
    assert_eq!(
        state["chamber"]["setpoint_c"], 23.0,
        "nothing written: {state:#}"
    );
    assert_eq!(
        state["table"]["demands_seen"], 0,
        "nothing moved: {state:#}"
    );
}
