//! The end-to-end fault matrix: `gyrocal sim` and `gyrocal run` as two processes talking over
//! pseudo-terminals through the real serial stack, in real time (the simulator's instruments
//! sped up by `--time-scale`; the sequencer's own waits are real seconds, hence the small plan).
//!
//! Each case asserts the run's outcome (exit code, manifest, CSV files) and the state of the
//! simulated table at the end (the simulator's final JSON line after SIGINT, or a probe of the
//! table's port between two runs). The virtual-time versions of the same logic are in
//! `crates/gyrocal-run/tests/sequencer_sim.rs` and `run_cli.rs`; these prove it on a serial port.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use common::manifest;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use gyrocal_link::{LinkOptions, Transport};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

/// Sim seconds per real second for the instruments.
const TIME_SCALE: &str = "30";
const SEED: &str = "11";
/// The plan's rates: every case runs these five steps.
const RATES: [f64; 5] = [0.0, 2.0, -2.0, 5.0, -5.0];
/// Readings per step (NPLC 1 with autozero: 30 × 40 ms = 1.2 sim s = 40 ms real).
const SAMPLES: u64 = 30;
/// The table's once-per-turn ripple in the plan, deg/s (see the clean case's allowance).
const RIPPLE_DPS: f64 = 0.0005;
/// Longest a single `gyrocal run` may take in these tests (a clean one takes about 3 s).
const RUN_LIMIT: Duration = Duration::from_secs(20);

/// A small plan in `dir`, with the `[simulation]` section the simulator is started from.
/// `[table]`/`[dmm]` ports are placeholders: the command line overrides them.
///
/// Written out key by key, not built from a `tests/support/plans.rs` plan: the fault
/// matrix's deadlines are timed against these exact settings (settle, stability window,
/// at-rate timeout, framing, acquisition, the table's rate noise and ripple), so a change to
/// a shipped plan or to the kit's minimal plan must not move them.
fn write_plan(dir: &Path) -> PathBuf {
    write_plan_with(dir, &RATES, 20.0)
}

/// The same plan with other rates and acceleration.
fn write_plan_with(dir: &Path, rates: &[f64], acceleration_dps2: f64) -> PathBuf {
    write_plan_full(dir, rates, acceleration_dps2, "acl")
}

/// The same plan with another table dialect too.
fn write_plan_full(dir: &Path, rates: &[f64], acceleration_dps2: f64, dialect: &str) -> PathBuf {
    let rates: Vec<String> = rates.iter().map(|r| format!("{r}")).collect();
    let text = format!(
        r#"[plan]
name = "e2e fault matrix"
rates_dps = [{rates}]
samples_per_rate = {SAMPLES}
settle_s = 0.2
repeat = 1
whole_revolutions = 0

[table]
dialect = "{dialect}"
port = "/dev/ttyUSB1"
baud = 9600
max_rate_dps = 10
acceleration_dps2 = {acceleration_dps2}
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
k2 = 0
k3 = 0
asymmetry = 0
noise_v = 0.002
bias_walk = 0
latitude_deg = 45.75
rate_noise_dps = 0.0002
ripple_dps = {RIPPLE_DPS}
"#,
        rates = rates.join(", ")
    );
    let path = dir.join("plan.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// A child process killed (and reaped) on drop, so a failed assertion leaves nothing running.
struct Guard {
    child: Child,
}

impl Guard {
    fn pid(&self) -> Pid {
        Pid::from_raw(i32::try_from(self.child.id()).unwrap())
    }

    fn signal(&self, sig: Signal) {
        kill(self.pid(), sig).unwrap();
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Collects a child's output stream line by line on a thread.
fn collect<R: Read + Send + 'static>(stream: R) -> (mpsc::Receiver<String>, Arc<Mutex<String>>) {
    let (tx, rx) = mpsc::channel();
    let all = Arc::new(Mutex::new(String::new()));
    let sink = Arc::clone(&all);
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines() {
            let Ok(line) = line else { break };
            {
                let mut s = sink.lock().unwrap();
                s.push_str(&line);
                s.push('\n');
            }
            let _ = tx.send(line);
        }
    });
    (rx, all)
}

/// A running `gyrocal sim` started from the plan.
struct Sim {
    guard: Guard,
    lines: mpsc::Receiver<String>,
    info: Value,
}

impl Sim {
    fn start(plan: &Path, faults: &[&str]) -> Sim {
        Sim::start_scaled(plan, faults, TIME_SCALE)
    }

    /// With another time scale (a slower bench makes a phase long enough to hit).
    fn start_scaled(plan: &Path, faults: &[&str], time_scale: &str) -> Sim {
        Sim::start_with(plan, faults, time_scale, &[])
    }

    /// With more arguments for `gyrocal sim` (`--link prologix-tcp`, ...).
    fn start_with(plan: &Path, faults: &[&str], time_scale: &str, extra: &[&str]) -> Sim {
        let mut cmd = common::gyrocal();
        cmd.env_remove("RUST_LOG")
            .env("GYROCAL_CATALOG", "off")
            .arg("sim")
            .arg("--config")
            .arg(plan)
            .args(["--time-scale", time_scale, "--seed", SEED])
            .args(extra);
        for f in faults {
            cmd.args(["--fault", f]);
        }
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let guard = Guard { child };
        let (lines, _) = collect(stdout);
        let first = lines
            .recv_timeout(Duration::from_secs(10))
            .expect("the simulator's JSON line with the device paths");
        let info: Value = serde_json::from_str(&first).unwrap();
        Sim { guard, lines, info }
    }

    /// The multimeter's port as a plan names it (a device path, `prologix:PATH?addr=22`,
    /// `prologix-tcp://127.0.0.1:P?addr=22`).
    fn dmm(&self) -> &str {
        self.info["dmm_port"].as_str().unwrap()
    }

    fn table(&self) -> &str {
        self.info["table"].as_str().unwrap()
    }

    /// SIGINT; the simulator's final-state line (and its clean exit).
    fn finish(mut self) -> Value {
        self.guard.signal(Signal::SIGINT);
        let last = self
            .lines
            .recv_timeout(Duration::from_secs(5))
            .expect("the simulator's final-state line");
        let status = self.guard.child.wait().unwrap();
        assert!(status.success(), "gyrocal sim exited with {status:?}");
        serde_json::from_str(&last).unwrap()
    }
}

/// A running `gyrocal run` against a simulator's ports.
struct Run {
    guard: Guard,
    stderr_lines: mpsc::Receiver<String>,
    stderr: Arc<Mutex<String>>,
    stdout: Arc<Mutex<String>>,
    started: Instant,
}

/// How a `gyrocal run` ended.
#[derive(Debug)]
struct Ended {
    code: Option<i32>,
    elapsed: Duration,
    stderr: String,
    stdout: String,
}

impl Run {
    /// `gyrocal run PLAN --dmm-port .. --table-port .. --no-report` plus `args`
    /// (`--out DIR` or `--resume DIR`), with `RUST_LOG` set to `log` when given.
    fn start(plan: &Path, sim: &Sim, args: &[&str], log: Option<&str>) -> Run {
        Run::start_cataloged(plan, sim, args, log, "off")
    }

    /// [`Run::start`] indexing the run in `catalog` (`GYROCAL_CATALOG`; `off`: none).
    fn start_cataloged(
        plan: &Path,
        sim: &Sim,
        args: &[&str],
        log: Option<&str>,
        catalog: &str,
    ) -> Run {
        let mut cmd = common::gyrocal();
        cmd.env_remove("RUST_LOG").env("GYROCAL_CATALOG", catalog);
        if let Some(l) = log {
            cmd.env("RUST_LOG", l);
        }
        let mut child = cmd
            .arg("run")
            .arg(plan)
            .args(["--dmm-port", sim.dmm(), "--table-port", sim.table()])
            .arg("--no-report")
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let out = child.stdout.take().unwrap();
        let err = child.stderr.take().unwrap();
        let guard = Guard { child };
        let (_, stdout) = collect(out);
        let (stderr_lines, stderr) = collect(err);
        Run {
            guard,
            stderr_lines,
            stderr,
            stdout,
            started: Instant::now(),
        }
    }

    /// Waits for the process to end (at most [`RUN_LIMIT`] from its start).
    fn wait(mut self) -> Ended {
        let code = loop {
            if let Some(status) = self.guard.child.try_wait().unwrap() {
                break status.code();
            }
            assert!(
                self.started.elapsed() < RUN_LIMIT,
                "gyrocal run still running after {RUN_LIMIT:?}; stderr:\n{}",
                self.stderr.lock().unwrap()
            );
            std::thread::sleep(Duration::from_millis(10));
        };
        let elapsed = self.started.elapsed();
        // the reader threads see EOF once the process is gone
        std::thread::sleep(Duration::from_millis(50));
        Ended {
            code,
            elapsed,
            stderr: self.stderr.lock().unwrap().clone(),
            stdout: self.stdout.lock().unwrap().clone(),
        }
    }

    /// Blocks until a stderr line satisfies `pred` (the run must still be running).
    fn wait_for_stderr(&self, what: &str, mut pred: impl FnMut(&str) -> bool) {
        loop {
            let left = RUN_LIMIT.saturating_sub(self.started.elapsed());
            match self.stderr_lines.recv_timeout(left) {
                Ok(line) if pred(&line) => return,
                Ok(_) => {}
                Err(_) => panic!(
                    "no stderr line for {what}; stderr:\n{}",
                    self.stderr.lock().unwrap()
                ),
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The run directory

/// Complete lines of a CSV file (a line torn by a killed writer is not one), header excluded.
fn csv_rows(path: &Path) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let complete = match text.rfind('\n') {
        Some(i) => &text[..=i],
        None => "",
    };
    let mut r = csv::Reader::from_reader(complete.as_bytes());
    let h = r.headers().unwrap().clone();
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            h.iter()
                .zip(rec.iter())
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

fn steps(dir: &Path) -> Vec<BTreeMap<String, String>> {
    csv_rows(&dir.join("steps.csv"))
}

fn samples(dir: &Path) -> Vec<BTreeMap<String, String>> {
    csv_rows(&dir.join("samples.csv"))
}

/// The 0-based schedule index of a row of steps.csv or samples.csv (its `step_no` minus one).
fn step_of(row: &BTreeMap<String, String>) -> usize {
    num::<usize>(row, "step_no") - 1
}

fn num<T: std::str::FromStr>(row: &BTreeMap<String, String>, key: &str) -> T
where
    T::Err: std::fmt::Debug,
{
    row[key]
        .parse()
        .unwrap_or_else(|e| panic!("{key} = {:?}: {e:?}", row[key]))
}

/// Every recorded step has all its samples, once each (a step may have left stray samples of
/// an unfinished acquisition behind it: a resume drops those).
fn check_recorded_steps_whole(dir: &Path) -> Vec<usize> {
    let mut per_step: BTreeMap<usize, BTreeSet<u64>> = BTreeMap::new();
    for s in samples(dir) {
        let fresh = per_step
            .entry(step_of(&s))
            .or_default()
            .insert(num::<u64>(&s, "sample_no") - 1);
        assert!(fresh, "duplicated sample {s:?}");
    }
    let mut done = Vec::new();
    for row in steps(dir) {
        let step = step_of(&row);
        let n: u64 = num(&row, "n");
        let overloads: u64 = num(&row, "overloads");
        assert_eq!(n + overloads, SAMPLES, "step row {row:?}");
        let got = per_step.get(&step).cloned().unwrap_or_default();
        assert_eq!(
            got,
            (0..SAMPLES).collect::<BTreeSet<_>>(),
            "step {step} is recorded, so all its samples are"
        );
        done.push(step);
    }
    done
}

/// The run is complete: every step exactly once, every sample exactly once, a fit.
fn check_complete(dir: &Path) {
    let m = manifest(dir);
    assert_eq!(m["status"], "complete", "{m}");
    let done = check_recorded_steps_whole(dir);
    let mut sorted = done.clone();
    sorted.sort_unstable();
    assert_eq!(
        sorted,
        (0..RATES.len()).collect::<Vec<_>>(),
        "every step exactly once: {done:?}"
    );
    let all = samples(dir);
    assert_eq!(
        all.len() as u64,
        RATES.len() as u64 * SAMPLES,
        "no lost or duplicated sample"
    );
    for row in steps(dir) {
        let step = step_of(&row);
        assert_eq!(num::<f64>(&row, "rate_dps"), RATES[step], "{row:?}");
    }
    assert!(dir.join("fit.json").exists(), "fit.json written");
}

// ---------------------------------------------------------------------------------------------
// The simulated table

/// The simulator's table was parked: stopped, or switched off / aborted with no rate demanded.
fn assert_table_parked(last: &Value) {
    let t = &last["table"];
    let parked = t["stopped"] == true
        || ((t["mode"] == "OFF" || t["mode"] == "ABORT") && t["demanded_rate"] == 0.0);
    assert!(parked, "table not stopped at the end: {last}");
}

/// Asks the table directly over its pseudo-terminal (the run has closed it): its mode and
/// measured rate. Raw ACL queries, so the probe changes nothing (no error-queue drain).
fn probe_table(path: &str) -> (String, f64) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let mut link = gyrocal_link::open(path, &LinkOptions::default())
            .await
            .unwrap();
        link.discard_input().await.unwrap();
        let t = Some(Duration::from_secs(2));
        link.send_line(":Mode? 1").await.unwrap();
        let mode = link.read_line(t).await.unwrap().trim().to_ascii_uppercase();
        link.send_line(":Read:Rate? 1").await.unwrap();
        let rate: f64 = link.read_line(t).await.unwrap().trim().parse().unwrap();
        (mode, rate)
    })
}

/// A table that could not be confirmed at rest is never said to be stopped: the last line
/// tells the operator to stop it by hand.
fn assert_not_called_at_rest(end: &Ended) {
    // gyrocal's own last line (log lines, which RUST_LOG may add, start with a timestamp)
    let last = end
        .stderr
        .lines()
        .rfind(|l| !l.starts_with("20"))
        .unwrap_or("");
    assert!(
        last.contains("could NOT be confirmed at rest") && last.contains("by hand"),
        "last line: {last}\n{}",
        end.stderr
    );
    assert!(
        !end.stderr.lines().any(|l| l.starts_with("table at rest")),
        "{}",
        end.stderr
    );
    assert!(!end.stderr.contains("sent a stop"), "{}", end.stderr);
}

fn fault_fired(last: &Value, spec: &str) -> bool {
    last["faults"]
        .as_array()
        .unwrap()
        .iter()
        .any(|f| f["spec"] == spec && f["fired"] == true)
}

fn start(tmp: &Path, faults: &[&str]) -> (PathBuf, Sim, PathBuf) {
    let plan = write_plan(tmp);
    let sim = Sim::start(&plan, faults);
    (plan, sim, tmp.join("run"))
}

fn out_args(dir: &Path) -> Vec<&str> {
    vec!["--out", dir.to_str().unwrap()]
}

fn resume_args(dir: &Path) -> Vec<&str> {
    vec!["--resume", dir.to_str().unwrap()]
}

// ---------------------------------------------------------------------------------------------
// 1. clean run

/// Weighted least-squares line through (x, y) with weights w: (K, K0).
fn weighted_line(x: &[f64], y: &[f64], w: &[f64]) -> (f64, f64) {
    let sw: f64 = w.iter().sum();
    let xm = x.iter().zip(w).map(|(x, w)| x * w).sum::<f64>() / sw;
    let ym = y.iter().zip(w).map(|(y, w)| y * w).sum::<f64>() / sw;
    let sxx: f64 = x.iter().zip(w).map(|(x, w)| w * (x - xm).powi(2)).sum();
    let sxy: f64 = x
        .iter()
        .zip(y)
        .zip(w)
        .map(|((x, y), w)| w * (x - xm) * (y - ym))
        .sum();
    let k = sxy / sxx;
    (k, ym - k * xm)
}

#[test]
fn e2e_clean_run_completes_and_its_fit_matches_the_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let (plan, sim, dir) = start(tmp.path(), &[]);
    let truth = sim.info["truth"].clone();
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    check_complete(&dir);
    assert!(manifest(&dir)["retries"].as_array().unwrap().is_empty());
    // the bench said it is a simulator (serial SIM0001): the run is recorded as simulated,
    // though started without --simulate
    let m = manifest(&dir);
    assert_eq!(m["simulated"], true, "{m}");
    assert!(
        m["simulated_by"].as_str().unwrap().contains("simulators"),
        "{m}"
    );
    assert!(end.stdout.contains("least-squares linear"), "{end:?}");

    let fit: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap();
    let lin = fit["fits"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["method"] == "least-squares" && f["model"] == "linear")
        .expect("a least-squares linear fit");
    assert_eq!(lin["weighted"], true, "{lin}");
    let k = lin["scale_factor"].as_f64().unwrap();
    let k0 = lin["bias"].as_f64().unwrap();
    let sk = lin["std_errors"]["k1"].as_f64().unwrap();
    let sk0 = lin["std_errors"]["k0"].as_f64().unwrap();

    // The truth's outputs at the plan's rates (what the gyro gives at exactly that table rate,
    // the Earth rate included), and the line the fit would find through them with the fit's
    // own weights n/σ²: for a linear truth it is K = k1, K0 = k0 + k1·Ω_E; with k2, k3 or an
    // asymmetry it is the best line through the curve, which is what a linear fit estimates.
    let f = |key: &str| truth[key].as_f64().unwrap();
    let rows = steps(&dir);
    let x: Vec<f64> = rows.iter().map(|r| num(r, "rate_dps")).collect();
    let w: Vec<f64> = rows
        .iter()
        .map(|r| num::<f64>(r, "n") / num::<f64>(r, "volts_std").powi(2))
        .collect();
    let y: Vec<f64> = x
        .iter()
        .map(|&rate| {
            let om = rate + f("earth_rate");
            let k1 = if om >= 0.0 { f("k1_pos") } else { f("k1_neg") };
            f("k0") + k1 * om + f("k2") * om * om + f("k3") * om.powi(3)
        })
        .collect();
    let (true_k, true_k0) = weighted_line(&x, &y, &w);

    // Model mismatch: the fit's abscissa is the demanded rate, the gyro feels the table's
    // actual rate, which carries the once-per-turn ripple (±RIPPLE_DPS). An acquisition lasts
    // ~1 sim second, a small part of a turn at these rates, so the ripple does not average
    // out: each step's mean may be off by up to E = K·ripple volts (the other sources are off
    // in this plan: bias walk 0, gyro white noise 0; the readback noise of the table does not
    // reach the gyro). A weighted line moves by at most
    //   |ΔK|  <= E·Σw|x−x̄| / Σw(x−x̄)²,   |ΔK0| <= E + |x̄|·|ΔK|
    // for errors bounded by E: that is the allowance, on top of 3 standard errors for noise.
    let kmax = f("k1_pos").max(f("k1_neg"));
    let e = kmax * RIPPLE_DPS;
    let sw: f64 = w.iter().sum();
    let xm = x.iter().zip(&w).map(|(x, w)| x * w).sum::<f64>() / sw;
    let sabs: f64 = x.iter().zip(&w).map(|(x, w)| w * (x - xm).abs()).sum();
    let sxx: f64 = x.iter().zip(&w).map(|(x, w)| w * (x - xm).powi(2)).sum();
    let allow_k = e * sabs / sxx;
    let allow_k0 = e + xm.abs() * allow_k;
    assert!(
        (k - true_k).abs() <= 3.0 * sk + allow_k,
        "K {k} ± {sk} vs truth {true_k} (allowance {allow_k:.2e})"
    );
    assert!(
        (k0 - true_k0).abs() <= 3.0 * sk0 + allow_k0,
        "K0 {k0} ± {sk0} vs truth {true_k0} (allowance {allow_k0:.2e})"
    );

    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert_table_parked(&last);
    assert_eq!(last["table"]["mode"], "OFF", "{last}");
    assert_eq!(last["table"]["demands_seen"], RATES.len(), "{last}");
    assert_eq!(
        last["dmm"]["readings_taken"],
        RATES.len() as u64 * SAMPLES,
        "no reading wasted: {last}"
    );
    assert_eq!(last["dmm"]["remote"], false, "meter back to local: {last}");
}

// ---------------------------------------------------------------------------------------------
// 2–4. multimeter faults the run rides through

/// A run with one multimeter fault in step 1 (reading 40 of 30 per step) that must complete
/// with a retry logged against that step.
fn retried_fault_completes(spec: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let (end, last, dir) = completes_with_retries(tmp.path(), spec, "dmm");
    let row = &steps(&dir)[1];
    assert!(num::<u32>(row, "retries") >= 1, "{row:?}");
    assert!(end.stderr.contains("retry (dmm)"), "{}", end.stderr);
    assert!(
        last["dmm"]["device_clears"].as_u64().unwrap() >= 1,
        "{last}"
    );
}

/// Runs the plan with one fault `spec` that must be ridden through: the run completes, every
/// retry in the manifest is `instrument`'s, and the fault fired. Returns the run's end, the
/// simulator's final state and the run directory (in `tmp`).
fn completes_with_retries(tmp: &Path, spec: &str, instrument: &str) -> (Ended, Value, PathBuf) {
    let (plan, sim, dir) = start(tmp, &[spec]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{spec}: {end:?}");
    check_complete(&dir);
    let m = manifest(&dir);
    let retries = m["retries"].as_array().unwrap();
    assert!(!retries.is_empty(), "{spec}: a retry is logged: {m}");
    assert!(
        retries
            .iter()
            .all(|r| r["instrument"] == instrument && r["step"] == 1),
        "{spec}: {retries:?}"
    );
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert!(fault_fired(&last, spec), "{last}");
    assert_table_parked(&last);
    (end, last, dir)
}

#[test]
fn e2e_multimeter_silent_for_one_reply_is_retried_and_the_run_completes() {
    retried_fault_completes("dmm:timeout@reading40");
}

#[test]
fn e2e_garbled_reply_is_retried_and_the_run_completes() {
    retried_fault_completes("dmm:garble@reading40");
}

#[test]
fn e2e_overload_readings_are_counted_and_excluded_not_repeated() {
    let spec = "dmm:overload@reading40x3";
    let tmp = tempfile::tempdir().unwrap();
    let (plan, sim, dir) = start(tmp.path(), &[spec]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    check_complete(&dir);
    // readings 40..42 are the 10th..12th of the second step (`step_no` 2)
    for row in steps(&dir) {
        let step = step_of(&row);
        let want = if step == 1 { 3 } else { 0 };
        assert_eq!(num::<u64>(&row, "overloads"), want, "{row:?}");
        assert_eq!(num::<u64>(&row, "n"), SAMPLES - want, "{row:?}");
    }
    let s1: Vec<_> = samples(&dir)
        .into_iter()
        .filter(|s| s["step_no"] == "2")
        .collect();
    let over: Vec<u64> = s1
        .iter()
        .filter(|s| s["overload"] == "1")
        .map(|s| num(s, "sample_no"))
        .collect();
    assert_eq!(over, vec![10, 11, 12], "overloads recorded as such");
    assert!(
        s1.iter()
            .filter(|s| s["overload"] == "1")
            .all(|s| s["volts"].is_empty())
    );
    // the step's mean is the mean of the valid readings only
    let valid: Vec<f64> = s1
        .iter()
        .filter(|s| s["overload"] == "0")
        .map(|s| num(s, "volts"))
        .collect();
    let mean = valid.iter().sum::<f64>() / valid.len() as f64;
    let recorded: f64 = num(&steps(&dir)[1], "volts");
    assert!(
        (mean - recorded).abs() < 1e-9,
        "{mean} vs recorded {recorded}"
    );
    assert!(recorded > 0.5 && recorded < 1.0, "2 °/s → about 0.72 V");
    assert!(manifest(&dir)["retries"].as_array().unwrap().is_empty());
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert!(fault_fired(&last, spec), "{last}");
    // the step was not repeated: the meter took exactly the plan's readings
    assert_eq!(
        last["dmm"]["readings_taken"],
        RATES.len() as u64 * SAMPLES,
        "{last}"
    );
    assert_table_parked(&last);
}

// ---------------------------------------------------------------------------------------------
// 5. multimeter disconnected

#[test]
fn e2e_multimeter_disconnect_fails_cleanly_and_resumes_on_a_new_bench() {
    let spec = "dmm:disconnect@reading40";
    let tmp = tempfile::tempdir().unwrap();
    let (plan, sim, dir) = start(tmp.path(), &[spec]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    let m = manifest(&dir);
    assert_eq!(m["status"], "failed", "{m}");
    let reason = m["reason"].as_str().unwrap();
    eprintln!("reason after {:?}: {reason}", end.elapsed);
    assert!(reason.contains("multimeter"), "{reason}");
    assert!(end.stderr.contains("resume with"), "{}", end.stderr);
    assert_eq!(check_recorded_steps_whole(&dir), vec![0]);
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert!(fault_fired(&last, spec), "{last}");
    assert_table_parked(&last);

    // the meter is gone for good: a new bench (same plan, same seed), the same run directory
    let sim = Sim::start(&plan, &[]);
    let end = Run::start(&plan, &sim, &resume_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    check_complete(&dir);
    let m = manifest(&dir);
    assert_eq!(m["resumes"].as_array().unwrap().len(), 1, "{m}");
    assert_eq!(m["resumes"][0]["steps_done"], 1, "{m}");
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert_eq!(
        last["dmm"]["readings_taken"],
        (RATES.len() as u64 - 1) * SAMPLES,
        "the resume runs only the steps left: {last}"
    );
    assert_table_parked(&last);
}

// ---------------------------------------------------------------------------------------------
// 6–7. table faults

#[test]
fn e2e_table_trip_fails_with_the_tables_message_and_the_table_stopped() {
    let spec = "table:trip@demand4";
    let tmp = tempfile::tempdir().unwrap();
    let (plan, sim, dir) = start(tmp.path(), &[spec]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    let m = manifest(&dir);
    assert_eq!(m["status"], "failed", "{m}");
    let reason = m["reason"].as_str().unwrap();
    eprintln!("reason after {:?}: {reason}", end.elapsed);
    assert!(reason.contains("rate table"), "{reason}");
    assert!(
        reason.contains("Rate trip"),
        "the table's own message: {reason}"
    );
    assert_eq!(check_recorded_steps_whole(&dir), vec![0, 1, 2]);
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert!(fault_fired(&last, spec), "{last}");
    assert_table_parked(&last);
    assert!(
        last["table"]["fault"]
            .as_str()
            .unwrap()
            .contains("Rate trip"),
        "{last}"
    );
}

#[test]
fn e2e_table_silent_from_a_demand_times_out_and_a_stop_is_attempted() {
    let spec = "table:silent@demand3";
    let tmp = tempfile::tempdir().unwrap();
    let (plan, sim, dir) = start(tmp.path(), &[spec]);
    // info from the table driver: it logs every stop command it sends
    let run = Run::start(
        &plan,
        &sim,
        &out_args(&dir),
        Some("warn,gyrocal_table=info,gyrocal_acl=info,gyrocal_aerosmith=info"),
    );
    let end = run.wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    // the demand goes unanswered: the driver's error-queue check after it times out (reply
    // timeout 1 s; a silent table mid-step misses its 2 s heartbeat instead, see below); the
    // cleanup is bounded too
    assert!(
        end.elapsed < Duration::from_secs(15),
        "failed after {:?}",
        end.elapsed
    );
    let m = manifest(&dir);
    assert_eq!(m["status"], "failed", "{m}");
    let reason = m["reason"].as_str().unwrap();
    eprintln!("reason after {:?}: {reason}", end.elapsed);
    assert!(reason.contains("rate table"), "{reason}");
    assert!(
        reason.contains("no answer") || reason.contains("deadline") || reason.contains("heartbeat"),
        "a timeout: {reason}"
    );
    assert_eq!(check_recorded_steps_whole(&dir), vec![0, 1]);
    // the stop was sent (a silent table ignores it: that is the point of the case)
    let stop_sent = end
        .stderr
        .lines()
        .filter(|l| l.contains(":Mode:Off") || l.contains(":Mode:Abort"))
        .count();
    assert!(stop_sent >= 1, "no stop attempted:\n{}", end.stderr);
    assert_not_called_at_rest(&end);
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert!(fault_fired(&last, spec), "{last}");
    let t = &last["table"];
    assert_eq!(t["silent"], true, "{last}");
    // what is true of a silent table: it ignored the 3rd demand and the stop, and still turns
    // at the 2nd step's rate
    assert_eq!(t["mode"], "RATE", "{last}");
    assert_eq!(t["demanded_rate"], RATES[1], "{last}");
    assert_eq!(t["stopped"], false, "{last}");
}

#[test]
fn e2e_table_silent_mid_acquisition_misses_its_heartbeat() {
    // silent from the middle of step 1's readings (31..60): the sequencer samples the table
    // every 200 ms while the meter reads, and each sample is a heartbeat with a 2 s deadline
    let spec = "table:silent@reading45";
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path());
    let dir = tmp.path().join("run");
    // a slower bench: 240 ms of readings per step, so a sample falls inside step 1's
    let sim = Sim::start_scaled(&plan, &[spec], "5");
    let run = Run::start(
        &plan,
        &sim,
        &out_args(&dir),
        Some("warn,gyrocal_table=info,gyrocal_acl=info,gyrocal_aerosmith=info"),
    );
    let end = run.wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    assert!(
        end.elapsed < Duration::from_secs(15),
        "failed after {:?}",
        end.elapsed
    );
    let m = manifest(&dir);
    assert_eq!(m["status"], "failed", "{m}");
    let reason = m["reason"].as_str().unwrap();
    eprintln!("reason after {:?}: {reason}", end.elapsed);
    assert!(reason.contains("rate table"), "{reason}");
    assert!(
        reason.contains(":Read:Rate?") && reason.contains("no answer"),
        "a missed heartbeat (a monitoring sample unanswered): {reason}"
    );
    // step 1 was cut short: not recorded
    assert_eq!(check_recorded_steps_whole(&dir), vec![0]);
    assert!(
        end.stderr.contains(":Mode:Off") || end.stderr.contains(":Mode:Abort"),
        "no stop attempted:\n{}",
        end.stderr
    );
    assert_not_called_at_rest(&end);
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert!(fault_fired(&last, spec), "{last}");
    let t = &last["table"];
    assert_eq!(t["silent"], true, "{last}");
    assert_eq!(t["mode"], "RATE", "{last}");
    assert_eq!(t["demanded_rate"], RATES[1], "{last}");
    assert_eq!(t["stopped"], false, "{last}");
}

// ---------------------------------------------------------------------------------------------
// 8–9. the operator and the operating system interrupt the run

/// Marks of the driver's debug line at the start of each acquisition (`RUST_LOG` below).
const ACQ_LOG: &str = "warn,gyrocal_hp34401a=debug";

fn is_acquisition_start(line: &str) -> bool {
    line.contains("acquisition") && line.contains("expected_s")
}

/// Blocks until the `k`-th acquisition (1-based) has started.
fn wait_acquisition(run: &Run, k: usize) {
    let mut seen = 0;
    run.wait_for_stderr("an acquisition start", |l| {
        if is_acquisition_start(l) {
            seen += 1;
        }
        seen == k
    });
}

#[test]
fn e2e_sigint_mid_acquisition_aborts_stops_the_table_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path());
    let dir = tmp.path().join("run");
    // a slower bench: an acquisition of 30 readings lasts 1.2 sim s = 240 ms here, so a
    // SIGINT 100 ms into it lands while the meter is reading
    let sim = Sim::start_scaled(&plan, &[], "5");
    let run = Run::start(&plan, &sim, &out_args(&dir), Some(ACQ_LOG));
    wait_acquisition(&run, 2);
    assert_eq!(
        steps(&dir).len(),
        1,
        "step 0 recorded before step 1 acquires"
    );
    std::thread::sleep(Duration::from_millis(100));
    run.guard.signal(Signal::SIGINT);
    let end = run.wait();
    assert_eq!(end.code, Some(130), "{end:?}");
    let m = manifest(&dir);
    assert_eq!(m["status"], "aborted", "{m}");
    assert!(m["reason"].as_str().unwrap().contains("SIGINT"), "{m}");
    // the interrupted step is not recorded, in either file
    assert_eq!(check_recorded_steps_whole(&dir), vec![0]);
    // the table was parked by the aborted run: ask it before anything else talks to it
    let (mode, rate) = probe_table(sim.table());
    assert!(mode == "OFF" || mode == "ABORT", "table mode {mode}");
    assert!(rate.abs() < 0.05, "table still turning at {rate} °/s");

    let end = Run::start(&plan, &sim, &resume_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    check_complete(&dir);
    let m = manifest(&dir);
    assert_eq!(m["resumes"].as_array().unwrap().len(), 1, "{m}");
    assert_eq!(m["resumes"][0]["steps_done"], 1, "{m}");
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert_table_parked(&last);
    assert_eq!(last["table"]["mode"], "OFF", "{last}");
    // the meter was stopped part-way through step 1's readings: more than the plan's readings
    // in all, fewer than one more step's worth (the interrupted ones were thrown away)
    let taken = last["dmm"]["readings_taken"].as_u64().unwrap();
    let plan_total = RATES.len() as u64 * SAMPLES;
    assert!(
        taken > plan_total && taken < plan_total + SAMPLES,
        "SIGINT mid-acquisition: {taken} readings taken for {plan_total} recorded"
    );
}

#[test]
fn e2e_sigkill_records_nothing_incomplete_and_resumes_with_the_table_turning() {
    let tmp = tempfile::tempdir().unwrap();
    let (plan, sim, dir) = start(tmp.path(), &[]);
    let run = Run::start(&plan, &sim, &out_args(&dir), Some(ACQ_LOG));
    // killed during step 2 (at -2 °/s): in its acquisition, or just after it if the machine is
    // slow; either way nothing may be recorded half
    wait_acquisition(&run, 3);
    std::thread::sleep(Duration::from_millis(10));
    run.guard.signal(Signal::SIGKILL);
    let end = run.wait();
    assert_eq!(end.code, None, "killed by a signal: {end:?}");
    assert_eq!(manifest(&dir)["status"], "running");
    let before = check_recorded_steps_whole(&dir);
    assert!(
        before == [0, 1] || before == [0, 1, 2],
        "recorded when killed: {before:?}"
    );
    // the dead process left the table turning at step 2's rate
    let (mode, rate) = probe_table(sim.table());
    assert_eq!(mode, "RATE", "the table was left in rate mode");
    assert!(
        (rate - RATES[2]).abs() < 0.05,
        "the table was left turning at -2 °/s: {rate} °/s"
    );

    let end = Run::start(&plan, &sim, &resume_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    check_complete(&dir);
    let m = manifest(&dir);
    assert_eq!(m["resumes"][0]["steps_done"], before.len(), "{m}");
    let last = sim.finish();
    eprintln!("simulator at the end: {last}");
    assert_table_parked(&last);
    assert_eq!(last["table"]["mode"], "OFF", "{last}");
}

// ---------------------------------------------------------------------------------------------
// 10–14. stop means at rest: every stop signal, a second signal, honest final words

/// A run at 10 °/s with a slow deceleration (5 °/s²: 2 sim s, 0.5 s here at time scale 4),
/// stopped by `sig` while the meter reads at rate. Returns the run's end, the simulator and
/// the run directory (in `tmp`).
fn stopped_at_speed(tmp: &Path, sig: Signal, second: Option<Signal>) -> (Ended, Sim, PathBuf) {
    stopped_at_speed_cataloged(tmp, sig, second, "off")
}

/// [`stopped_at_speed`] with the run indexed in `catalog`.
fn stopped_at_speed_cataloged(
    tmp: &Path,
    sig: Signal,
    second: Option<Signal>,
    catalog: &str,
) -> (Ended, Sim, PathBuf) {
    let plan = write_plan_with(tmp, &[0.0, 10.0], 5.0);
    let dir = tmp.join("run");
    let sim = Sim::start_scaled(&plan, &[], "4");
    let run = Run::start_cataloged(&plan, &sim, &out_args(&dir), Some(ACQ_LOG), catalog);
    wait_acquisition(&run, 2);
    std::thread::sleep(Duration::from_millis(100));
    run.guard.signal(sig);
    if let Some(again) = second {
        run.wait_for_stderr("the deceleration", |l| l.contains("decelerating from"));
        run.guard.signal(again);
    }
    let end = run.wait();
    (end, sim, dir)
}

fn stop_signal_waits_for_rest(sig: Signal, code: i32) {
    let tmp = tempfile::tempdir().unwrap();
    let (end, sim, dir) = stopped_at_speed(tmp.path(), sig, None);
    // the table is asked the moment gyrocal has exited: at rest, not still decelerating (a
    // 0.5 s deceleration here; exiting right after the stop command left it near 10 °/s)
    let (mode, rate) = probe_table(sim.table());
    assert_eq!(end.code, Some(code), "{sig}: {end:?}");
    assert_eq!(mode, "OFF", "{sig}");
    assert!(
        rate.abs() < 0.05,
        "{sig}: gyrocal exited with the table at {rate} °/s"
    );
    let m = manifest(&dir);
    assert_eq!(m["status"], "aborted", "{m}");
    let name = format!("{sig:?}");
    assert!(m["reason"].as_str().unwrap().contains(&name), "{m}");
    // the operator saw the deceleration and the rest, and the last line says so
    let from: f64 = end
        .stderr
        .lines()
        .find_map(|l| l.split("table decelerating from ").nth(1))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|x| x.parse().ok())
        .unwrap_or_else(|| panic!("{sig}: no deceleration line:\n{}", end.stderr));
    assert!(
        (from - 10.0).abs() < 0.05,
        "{sig}: decelerating from {from}"
    );
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert!(!end.stderr.contains("sent a stop"), "{}", end.stderr);
    assert_eq!(check_recorded_steps_whole(&dir), vec![0]);
    let last = sim.finish();
    assert_table_parked(&last);
    assert_eq!(
        last["table"]["interlock_closed"], true,
        "a controlled stop only: {last}"
    );
}

/// A stop at speed with the run indexed in a catalog: the catalog's writer and its bounded
/// wait at the end come after the table is at rest, and never stand in its way.
fn stop_at_speed_with_a_catalog(catalog: &str) -> (Ended, tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let (end, sim, dir) = stopped_at_speed_cataloged(tmp.path(), Signal::SIGINT, None, catalog);
    let (mode, rate) = probe_table(sim.table());
    assert_eq!(end.code, Some(130), "{end:?}");
    assert_eq!(mode, "OFF");
    assert!(
        rate.abs() < 0.05,
        "gyrocal exited with the table at {rate} °/s"
    );
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(manifest(&dir)["status"], "aborted");
    let last = sim.finish();
    assert_table_parked(&last);
    (end, tmp, dir)
}

#[test]
fn e2e_sigint_with_a_catalog_stops_the_table_and_the_catalog_has_the_abort() {
    let db = tempfile::tempdir().unwrap();
    let url = format!("sqlite:{}", db.path().join("lab.sqlite").display());
    let (end, _tmp, dir) = stop_at_speed_with_a_catalog(&url);
    assert!(
        !end.stderr.contains("could not be updated"),
        "{}",
        end.stderr
    );
    let out = common::gyrocal()
        .env_remove("RUST_LOG")
        .args(["runs", "--json", "--catalog", &url])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let runs: Value = serde_json::from_slice(&out.stdout).unwrap();
    let row = &runs[0];
    assert_eq!(row["status"], "aborted", "{runs}");
    assert_eq!(
        row["directory"],
        std::fs::canonicalize(&dir).unwrap().display().to_string()
    );
}

#[test]
fn e2e_sigint_with_an_unreachable_catalog_stops_the_table_and_says_the_catalog_missed_it() {
    // nothing listens on port 1: the catalog cannot be reached at any point of the run
    let (end, _tmp, dir) = stop_at_speed_with_a_catalog("postgres://gyrocal@127.0.0.1:1/nowhere");
    let warning = end
        .stderr
        .lines()
        .find(|l| l.contains("could not be updated"))
        .unwrap_or_else(|| {
            panic!(
                "no catalog warning:
{}",
                end.stderr
            )
        });
    assert!(
        warning.contains("gyrocal catalog import") && warning.contains(dir.to_str().unwrap()),
        "{warning}"
    );
    // the operator reads about the table before the catalog
    let at_rest = end.stderr.find("table at rest").unwrap();
    assert!(
        at_rest < end.stderr.find(warning).unwrap(),
        "{}",
        end.stderr
    );
}

#[test]
fn e2e_sigint_exits_130_only_once_the_table_is_at_rest() {
    stop_signal_waits_for_rest(Signal::SIGINT, 130);
}

#[test]
fn e2e_sigterm_exits_143_only_once_the_table_is_at_rest() {
    stop_signal_waits_for_rest(Signal::SIGTERM, 143);
}

#[test]
fn e2e_sighup_exits_129_only_once_the_table_is_at_rest() {
    stop_signal_waits_for_rest(Signal::SIGHUP, 129);
}

#[test]
fn e2e_sigquit_exits_131_only_once_the_table_is_at_rest() {
    stop_signal_waits_for_rest(Signal::SIGQUIT, 131);
}

#[test]
fn e2e_a_second_signal_during_the_deceleration_is_the_emergency_stop() {
    let tmp = tempfile::tempdir().unwrap();
    let (end, sim, dir) = stopped_at_speed(tmp.path(), Signal::SIGINT, Some(Signal::SIGHUP));
    let (mode, rate) = probe_table(sim.table());
    assert_eq!(
        end.code,
        Some(130),
        "the first signal names the exit: {end:?}"
    );
    assert!(end.stderr.contains("EMERGENCY STOP"), "{}", end.stderr);
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(mode, "OFF");
    assert!(rate.abs() < 0.05, "table at {rate} °/s");
    assert_eq!(manifest(&dir)["status"], "aborted");
    // recorded as the emergency stop it was, not as the controlled stop asked for first, and
    // the operator is told to re-arm the interlock before the resume
    let reason = manifest(&dir)["reason"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(reason.contains("emergency stop"), "{reason}");
    assert!(
        end.stderr.contains("re-arm the interlock"),
        "{}",
        end.stderr
    );
    let last = sim.finish();
    // the emergency stop opened the interlock (servo off)
    assert_eq!(last["table"]["interlock_closed"], false, "{last}");
}

// ---------------------------------------------------------------------------------------------
// 15–20. a faulted step is never recorded; link transients and a meter power cycle are survived

/// A table fault in the middle of step 1's readings (bench at time scale 5: the acquisition
/// lasts 240 ms, the sequencer samples the table every 200 ms and once more after the last
/// reading): the run fails with the table's message and step 1 is not recorded.
fn table_fault_mid_acquisition_is_not_recorded(spec: &str, message: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path());
    let dir = tmp.path().join("run");
    let sim = Sim::start_scaled(&plan, &[spec], "5");
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    let m = manifest(&dir);
    assert_eq!(m["status"], "failed", "{m}");
    let reason = m["reason"].as_str().unwrap();
    assert!(reason.contains(message), "{spec}: {reason}");
    assert_eq!(
        check_recorded_steps_whole(&dir),
        vec![0],
        "{spec}: the faulted step 1 must not be recorded"
    );
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    let last = sim.finish();
    assert!(fault_fired(&last, spec), "{last}");
    assert!(
        last["table"]["actual_rate"].as_f64().unwrap().abs() < 0.05,
        "{last}"
    );
}

#[test]
fn e2e_table_fault_mid_acquisition_is_never_recorded() {
    table_fault_mid_acquisition_is_not_recorded(
        "table:fault@reading45",
        "Tracking error limit exceeded",
    );
}

#[test]
fn e2e_interlock_opened_mid_acquisition_is_never_recorded() {
    table_fault_mid_acquisition_is_not_recorded("table:interlock@reading45", "Interlock open");
}

/// One table link transient during step 1: retried, logged against the table, run complete.
fn table_transient_is_retried(spec: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let (end, _, dir) = completes_with_retries(tmp.path(), spec, "table");
    let m = manifest(&dir);
    assert!(
        m["retries"]
            .as_array()
            .unwrap()
            .iter()
            .any(|r| r["message"].as_str().unwrap().contains("asked again")),
        "{m}"
    );
    assert!(end.stderr.contains("retry (table)"), "{}", end.stderr);
}

#[test]
fn e2e_a_lost_table_reply_is_asked_again() {
    table_transient_is_retried("table:drop@reading40");
}

#[test]
fn e2e_a_garbled_table_reply_is_asked_again() {
    table_transient_is_retried("table:garble@reading40");
}

#[test]
fn e2e_a_noise_byte_on_the_table_link_is_survived() {
    table_transient_is_retried("table:noise@reading40");
}

#[test]
fn e2e_a_meter_power_cycle_is_recovered_and_the_run_completes() {
    // off for 2 sim s (67 ms here) in the middle of step 1, back in LOCAL at 10 PLC
    let spec = "dmm:powercycle@reading40/2s";
    let tmp = tempfile::tempdir().unwrap();
    let (_, last, dir) = completes_with_retries(tmp.path(), spec, "dmm");
    let m = manifest(&dir);
    assert!(
        m["retries"]
            .as_array()
            .unwrap()
            .iter()
            .any(|r| r["message"].as_str().unwrap().contains("re-established")),
        "{m}"
    );
    assert_eq!(last["dmm"]["power_cycles"], 1, "{last}");
    // measuring at the plan's 1 PLC again, and handed back to local at the end
    assert_eq!(last["dmm"]["nplc"], 1.0, "{last}");
    assert_eq!(last["dmm"]["remote"], false, "{last}");
}

// ---------------------------------------------------------------------------------------------
// 21–22. the experimental Ideal Aerosmith dialect: the same run, the same safety

#[test]
fn e2e_aerosmith_table_clean_run_completes_with_the_table_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan_full(tmp.path(), &RATES, 20.0, "aerosmith");
    let dir = tmp.path().join("run");
    let sim = Sim::start(&plan, &[]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    check_complete(&dir);
    assert!(
        end.stderr.contains("rate table: Ideal Aerosmith"),
        "{}",
        end.stderr
    );
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    let last = sim.finish();
    assert_table_parked(&last);
}

#[test]
fn e2e_aerosmith_table_sigint_at_speed_exits_only_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan_full(tmp.path(), &[0.0, 10.0], 5.0, "aerosmith");
    let dir = tmp.path().join("run");
    let sim = Sim::start_scaled(&plan, &[], "4");
    let run = Run::start(&plan, &sim, &out_args(&dir), Some(ACQ_LOG));
    wait_acquisition(&run, 2);
    std::thread::sleep(Duration::from_millis(100));
    run.guard.signal(Signal::SIGINT);
    let end = run.wait();
    assert_eq!(end.code, Some(130), "{end:?}");
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(check_recorded_steps_whole(&dir), vec![0]);
    let last = sim.finish();
    assert!(
        last["table"]["actual_rate"].as_f64().unwrap().abs() < 0.05,
        "{last}"
    );
}

#[test]
fn e2e_meter_over_gpib_through_a_prologix_controller_completes() {
    // the plan names a Prologix port: `gyrocal sim` serves a simulated controller on the
    // meter's pseudo-terminal, `gyrocal run` opens it as prologix:PATH?addr=22
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path());
    let text = std::fs::read_to_string(&plan).unwrap().replace(
        "port = \"/dev/ttyUSB0\"",
        "port = \"prologix:/dev/ttyUSB0?addr=22\"",
    );
    std::fs::write(&plan, text).unwrap();
    let dir = tmp.path().join("run");
    let sim = Sim::start(&plan, &[]);
    // the simulator says the port a plan names for it
    let dmm_port = sim.dmm().to_string();
    assert!(dmm_port.starts_with("prologix:/dev/"), "{dmm_port}");
    let mut cmd = common::gyrocal();
    let out = cmd
        .env_remove("RUST_LOG")
        .env("GYROCAL_CATALOG", "off")
        .arg("run")
        .arg(&plan)
        .args(["--dmm-port", &dmm_port, "--table-port", sim.table()])
        .args(["--no-report", "--out", dir.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    check_complete(&dir);
    let last = sim.finish();
    assert_table_parked(&last);
    // GPIB: the meter was never sent SYST:REM (it would have refused it with -113)
    assert_eq!(last["dmm"]["errors_raised"], 0, "{last}");
}

#[test]
fn e2e_aerosmith_table_gone_silent_is_never_called_at_rest() {
    // silent from the middle of step 1's readings: the operator is told plainly that rest
    // could not be confirmed, and the simulated table does still turn
    let spec = "table:silent@reading45";
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan_full(tmp.path(), &RATES, 20.0, "aerosmith");
    let dir = tmp.path().join("run");
    let sim = Sim::start_scaled(&plan, &[spec], "5");
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    assert_not_called_at_rest(&end);
    assert_eq!(check_recorded_steps_whole(&dir), vec![0]);
    let last = sim.finish();
    assert!(fault_fired(&last, spec), "{last}");
    assert_eq!(last["table"]["stopped"], false, "{last}");
}

// ---------------------------------------------------------------------------------------------
// the 34401A on GPIB: behind a simulated Prologix GPIB-USB controller (pseudo-terminal) and a
// GPIB-ETHERNET one (TCP), through the real Prologix transport

#[test]
fn e2e_prologix_usb_and_ethernet_run_the_plan_with_a_retried_fault_and_stop_at_rest() {
    for link in ["prologix", "prologix-tcp"] {
        let tmp = tempfile::tempdir().unwrap();
        let plan = write_plan(tmp.path());
        let spec = "dmm:garble@reading40";
        let sim = Sim::start_with(&plan, &[spec], TIME_SCALE, &["--link", link]);
        let port = sim.dmm().to_string();
        let scheme = if link == "prologix" {
            "prologix:/dev/"
        } else {
            "prologix-tcp://127.0.0.1:"
        };
        assert!(port.starts_with(scheme), "{link}: {port}");
        let dir = tmp.path().join("run");
        let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
        assert_eq!(end.code, Some(0), "{link}: {end:?}");
        check_complete(&dir);
        let m = manifest(&dir);
        let dmm_retries = m["retries"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["instrument"] == "dmm")
            .count();
        assert!(
            dmm_retries >= 1,
            "{link}: the garbled reading was retried: {m}"
        );
        assert!(
            end.stderr.contains("table at rest"),
            "{link}: {}",
            end.stderr
        );
        let last = sim.finish();
        assert!(fault_fired(&last, spec), "{link}: {last}");
        assert_eq!(last["table"]["stopped"], true, "{link}: {last}");
        // over GPIB the meter gets no SYST:REM (an RS-232-only command) and is handed back
        // to its front panel by the controller's ++loc
        assert_eq!(last["dmm"]["errors_raised"], 0, "{link}: {last}");
    }
}

// ---------------------------------------------------------------------------------------------
// the connection probe

#[test]
fn e2e_check_probe_identifies_both_instruments_and_a_silent_meter_leaves_no_run_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path());
    let sim = Sim::start(&plan, &[]);
    let out = common::gyrocal()
        .env_remove("RUST_LOG")
        .env("GYROCAL_CATALOG", "off")
        .arg("check")
        .arg(&plan)
        .args([
            "--probe",
            "--dmm-port",
            sim.dmm(),
            "--table-port",
            sim.table(),
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("probe: multimeter HEWLETT-PACKARD,34401A,SIM0001"),
        "{stdout}"
    );
    assert!(
        stdout.contains("probe: rate table ACUTRONIC,ACUTROL3000,SIM0001"),
        "{stdout}"
    );
    assert!(stdout.contains("(mode Off"), "{stdout}");
    // the same as one JSON document
    let out = common::gyrocal()
        .env_remove("RUST_LOG")
        .env("GYROCAL_CATALOG", "off")
        .arg("check")
        .arg(&plan)
        .args([
            "--json",
            "--probe",
            "--dmm-port",
            sim.dmm(),
            "--table-port",
            sim.table(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["probe"]["answered"], true, "{doc}");
    assert!(
        doc["probe"]["table"].as_str().unwrap().contains("SIM0001"),
        "{doc}"
    );

    // a meter port where nothing answers (a pseudo-terminal nobody serves)
    let pty = nix::pty::openpty(None, None).unwrap();
    let silent = nix::unistd::ttyname(&pty.slave).unwrap();
    let dir = tmp.path().join("run");
    let out = common::gyrocal()
        .env_remove("RUST_LOG")
        .env("GYROCAL_CATALOG", "off")
        .arg("run")
        .arg(&plan)
        .args([
            "--dmm-port",
            silent.to_str().unwrap(),
            "--table-port",
            sim.table(),
        ])
        .args(["--no-report", "--out", dir.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "the multimeter at {} did not answer",
            silent.display()
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains("9600 baud and 8N2") && stderr.contains("null-modem"),
        "the likely causes for RS-232: {stderr}"
    );
    assert!(
        !dir.exists(),
        "nothing created on disk when an instrument does not answer"
    );
    drop(pty);
    let last = sim.finish();
    assert_eq!(last["table"]["demands_seen"], 0, "{last}");
}

/// A run measured on instruments that do not identify as simulators, resumed against
/// `gyrocal sim` (which does): refused before the table moves, over pseudo-terminals, and the
/// operator is told the table is at rest.
#[test]
fn e2e_a_measured_run_is_not_continued_on_a_simulator_and_the_table_ends_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path());
    let dir = tmp.path().join("run");
    // a bench whose instruments answer as real ones do (serial fields 0 and 1234)
    let bench = tmp.path().join("bench.toml");
    std::fs::write(
        &bench,
        "seed = 11\n[dmm]\nidentity = \"HEWLETT-PACKARD,34401A,0,11-5-2\"\n\
         [table]\nidentity = \"ACUTRONIC,ACUTROL3000,1234,3.1\"\n",
    )
    .unwrap();
    let spec = "table:trip@demand3";
    let looks_real = Sim::start_with(&bench, &[spec], TIME_SCALE, &[]);
    let end = Run::start(&plan, &looks_real, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    assert_eq!(check_recorded_steps_whole(&dir), vec![0, 1]);
    assert_eq!(manifest(&dir)["simulated"], false);
    let _ = looks_real.finish();

    let sim = Sim::start(&plan, &[]);
    let end = Run::start(&plan, &sim, &resume_args(&dir), None).wait();
    assert_eq!(end.code, Some(1), "{end:?}");
    assert!(
        end.stderr.contains("mix simulated and measured data"),
        "{}",
        end.stderr
    );
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(
        check_recorded_steps_whole(&dir),
        vec![0, 1],
        "nothing recorded"
    );
    let last = sim.finish();
    assert_eq!(last["table"]["demands_seen"], 0, "never moved: {last}");
    assert_eq!(last["table"]["stopped"], true, "{last}");
}

#[test]
fn e2e_sigint_during_the_warm_up_stops_the_table_and_records_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_plan(tmp.path());
    // a warm-up that cannot settle (tolerance far below the readings' noise) and lasts
    // 60 sim s at most: the SIGINT lands in it
    let mut text = std::fs::read_to_string(&plan).unwrap();
    text.push_str("\n[warmup]\nwindow_s = 1\ntolerance_v = 1e-12\nmax_s = 60\n");
    std::fs::write(&plan, text).unwrap();
    let dir = tmp.path().join("run");
    let sim = Sim::start_scaled(&plan, &[], "5");
    let run = Run::start(&plan, &sim, &out_args(&dir), None);
    // the warm-up has begun when the manifest holds its first window means
    let t0 = std::time::Instant::now();
    loop {
        let m = std::fs::read_to_string(dir.join("manifest.json")).unwrap_or_default();
        let v: Value = serde_json::from_str(&m).unwrap_or(Value::Null);
        if v["warmup"]["means"]
            .as_array()
            .is_some_and(|a| a.len() >= 2)
        {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "no warm-up seen");
        std::thread::sleep(Duration::from_millis(20));
    }
    run.guard.signal(Signal::SIGINT);
    let end = run.wait();
    assert_eq!(end.code, Some(130), "{end:?}");
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    let m = manifest(&dir);
    assert_eq!(m["status"], "aborted", "{m}");
    assert_eq!(m["warmup"]["complete"], false, "{m}");
    assert!(steps(&dir).is_empty(), "no step before the warm-up ends");
    // the table was parked: ask it on its own port
    let (mode, rate) = probe_table(sim.table());
    assert!(mode == "OFF" || mode == "ABORT", "table mode {mode}");
    assert!(rate.abs() < 0.05, "table still turning at {rate} °/s");
    let last = sim.finish();
    assert_table_parked(&last);
}

#[test]
fn e2e_a_drift_record_without_a_table_never_talks_to_one() {
    let tmp = tempfile::tempdir().unwrap();
    // a drift record on a bench without a table: no [table] section. The plan's exact text is
    // what the test is about (no `[table]` at all, `table = "none"`), so it stays a literal
    // rather than a kit plan with a section cut out.
    let plan = tmp.path().join("plan.toml");
    std::fs::write(
        &plan,
        r#"[plan]
kind = "drift"
name = "e2e drift without a table"
rates_dps = [0]
samples_per_rate = 100
repeat = 3
settle_s = 0

[drift]
table = "none"

[dmm]
port = "/dev/ttyUSB0"
nplc = 1
autozero = false

[simulation]
seed = 3
noise_v = 0.0001
"#,
    )
    .unwrap();
    let dir = tmp.path().join("run");
    // the simulator serves a table too; the run must leave it alone
    let sim = Sim::start(&plan, &[]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    assert!(
        end.stderr.contains("no rate table in this plan"),
        "{}",
        end.stderr
    );
    assert_eq!(steps(&dir).len(), 3);
    let last = sim.finish();
    assert_eq!(last["table"]["demands_seen"], 0, "{last}");
    assert!(
        last["dmm"]["readings_taken"].as_u64().unwrap() >= 300,
        "{last}"
    );
}

/// A drift plan of `segments` segments of 150 readings with `[drift] table = ROLE` (`none`:
/// no `[table]` section).
fn write_drift_plan(dir: &Path, role: &str, segments: u32) -> PathBuf {
    let table = if role == "none" {
        String::new()
    } else {
        "[table]\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 10\nacceleration_dps2 = 20\n\
         rate_tolerance_dps = 0.01\nstability_window_s = 0.2\nat_rate_timeout_s = 10\n\n"
            .to_string()
    };
    let text = format!(
        "[plan]\nkind = \"drift\"\nname = \"e2e drift, table {role}\"\nrates_dps = [0]\n\
         samples_per_rate = 150\nrepeat = {segments}\nsettle_s = 0\n\n[drift]\ntable = \"{role}\"\n\n\
         {table}[dmm]\nport = \"/dev/ttyUSB0\"\nnplc = 1\nautozero = false\n\n\
         [simulation]\nseed = 3\nnoise_v = 0.0001\nrate_noise_dps = 0\nripple_dps = 0\n"
    );
    let path = dir.join("drift.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Waits until `n` segments of the run in `dir` are recorded.
fn wait_segments(dir: &Path, n: usize) {
    let t0 = Instant::now();
    while !dir.join("steps.csv").exists() || steps(dir).len() < n {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no segment recorded"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn e2e_sigint_during_a_servo_off_drift_record_leaves_the_table_at_rest_with_its_servo_off() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_drift_plan(tmp.path(), "servo_off", 40);
    let dir = tmp.path().join("run");
    let sim = Sim::start_scaled(&plan, &[], "5");
    let run = Run::start(&plan, &sim, &out_args(&dir), None);
    wait_segments(&dir, 1);
    run.guard.signal(Signal::SIGINT);
    let end = run.wait();
    assert_eq!(end.code, Some(130), "{end:?}");
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(manifest(&dir)["status"], "aborted");
    // asked on its own port after the exit: OFF, not turning
    let (mode, rate) = probe_table(sim.table());
    assert!(mode == "OFF" || mode == "ABORT", "table mode {mode}");
    assert!(rate.abs() < 0.05, "table turning at {rate} °/s");
    let last = sim.finish();
    assert_table_parked(&last);
    assert_eq!(last["table"]["interlock_closed"], false, "{last}");
    assert_eq!(
        last["table"]["demands_seen"], 0,
        "never given a rate: {last}"
    );
}

#[test]
fn e2e_sigint_during_a_record_without_a_table_says_nothing_was_moved() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_drift_plan(tmp.path(), "none", 40);
    let dir = tmp.path().join("run");
    let sim = Sim::start_scaled(&plan, &[], "5");
    let run = Run::start(&plan, &sim, &out_args(&dir), None);
    wait_segments(&dir, 1);
    run.guard.signal(Signal::SIGINT);
    let end = run.wait();
    assert_eq!(end.code, Some(130), "{end:?}");
    assert!(
        end.stderr
            .contains("no rate table in this plan: nothing was moved"),
        "{}",
        end.stderr
    );
    assert!(!end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(manifest(&dir)["status"], "aborted");
    let last = sim.finish();
    assert_eq!(last["table"]["demands_seen"], 0, "{last}");
}

// ---------------------------------------------------------------------------------------------
// The slow table over pseudo-terminals: replies held back, never taken for another query's

/// `count` table replies held back by `real_s` real seconds from reading 40 (step 1) on, on the
/// bench at the usual time scale (more would outlast the test's 20 s bound on the run): the run completes, each recorded step's measured table rate is
/// its own (a status byte, an error entry or a mode taken for a rate would show), the late
/// replies are said to be recognised and the table to answer slowly, and the table ends parked.
fn slow_table_completes(real_s: f64, count: u32) {
    let tmp = tempfile::tempdir().unwrap();
    let scale: f64 = TIME_SCALE.parse().unwrap();
    let spec = format!("table:slow@reading40x{count}/{}s", real_s * scale);
    let (plan, sim, dir) = start(tmp.path(), &[&spec]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{spec}: {end:?}");
    check_complete(&dir);
    for row in steps(&dir) {
        let demanded: f64 = num(&row, "rate_dps");
        let measured: f64 = num(&row, "rate_meas_dps");
        assert!(
            (measured - demanded).abs() < 0.01,
            "{spec}: step at {demanded} °/s recorded a table rate of {measured} °/s"
        );
    }
    let m = manifest(&dir);
    let said =
        |what: &str| {
            m["retries"].as_array().unwrap().iter().any(|r| {
                r["instrument"] == "table" && r["message"].as_str().unwrap().contains(what)
            })
        };
    assert!(said("the table answers slowly"), "{spec}: {m}");
    assert!(said("discarded"), "{spec}: {m}");
    assert!(
        end.stderr.contains("the table answers slowly"),
        "{}",
        end.stderr
    );
    // asked on its own port the moment gyrocal has exited (the held-back replies are used up)
    let (mode, rate) = probe_table(sim.table());
    assert_eq!(mode, "OFF", "{spec}");
    assert!(rate.abs() < 0.05, "{spec}: table at {rate} °/s");
    let last = sim.finish();
    assert!(fault_fired(&last, &spec), "{last}");
    assert_table_parked(&last);
}

#[test]
fn e2e_a_table_whose_replies_come_half_a_second_late_keeps_in_step() {
    slow_table_completes(0.5, 20);
}

#[test]
fn e2e_a_table_whose_replies_come_1_2_s_late_keeps_in_step() {
    slow_table_completes(1.2, 8);
}

// ---------------------------------------------------------------------------------------------
// A servo-off drift record that ends (complete, or resumed after a SIGINT) over
// pseudo-terminals: the engine's other setup (rest, then the servo switched off through the
// interlock) and the same teardown and ending as a sweep's

#[test]
fn e2e_a_servo_off_drift_record_completes_with_the_table_off_and_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_drift_plan(tmp.path(), "servo_off", 3);
    let dir = tmp.path().join("run");
    let sim = Sim::start(&plan, &[]);
    let end = Run::start(&plan, &sim, &out_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(manifest(&dir)["status"], "complete");
    assert_eq!(steps(&dir).len(), 3);
    let (mode, rate) = probe_table(sim.table());
    assert_eq!(mode, "OFF", "the servo is off after the record");
    assert!(rate.abs() < 0.05, "table turning at {rate} °/s");
    let last = sim.finish();
    assert_table_parked(&last);
    assert_eq!(
        last["table"]["demands_seen"], 0,
        "never given a rate: {last}"
    );
}

#[test]
fn e2e_a_servo_off_drift_record_stopped_by_sigint_resumes_to_completion_at_rest() {
    let tmp = tempfile::tempdir().unwrap();
    let plan = write_drift_plan(tmp.path(), "servo_off", 4);
    let dir = tmp.path().join("run");
    let sim = Sim::start_scaled(&plan, &[], "5");
    let run = Run::start(&plan, &sim, &out_args(&dir), None);
    wait_segments(&dir, 1);
    run.guard.signal(Signal::SIGINT);
    let end = run.wait();
    assert_eq!(end.code, Some(130), "{end:?}");
    let done = steps(&dir).len();
    assert!(done < 4, "stopped part-way: {done} segments");

    let end = Run::start(&plan, &sim, &resume_args(&dir), None).wait();
    assert_eq!(end.code, Some(0), "{end:?}");
    assert!(end.stderr.contains("table at rest"), "{}", end.stderr);
    assert_eq!(manifest(&dir)["status"], "complete");
    assert_eq!(steps(&dir).len(), 4, "every segment once");
    let (mode, rate) = probe_table(sim.table());
    assert_eq!(mode, "OFF", "the servo stays off");
    assert!(rate.abs() < 0.05, "table turning at {rate} °/s");
    let last = sim.finish();
    assert_table_parked(&last);
    assert_eq!(
        last["table"]["demands_seen"], 0,
        "never given a rate: {last}"
    );
}
