//! Safety and data integrity of the sequencer against the simulated bench, in virtual time:
//! a run ends only with the table at rest (or says plainly that it could not confirm it), a
//! second stop request during the deceleration is the emergency stop, a panic still brings the
//! table to rest, and a step the table did not hold for its whole acquisition is never
//! recorded.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)] // test helpers

mod common;

use std::path::Path;
use std::time::Duration;

use common::{config, new_run, plan_with_rates, table_config};
use gyrocal_acl::AclTable;
use gyrocal_files::{Plan, Status, load};
use gyrocal_run::{Event, Phase, RunSummary, Sequencer, SequencerOptions, StopRequest, TableRest};
use gyrocal_sim::bench::{Bench, BenchHandle};
use gyrocal_sim::from_plan::bench_config;
use gyrocal_sim::table::SimMode;
use gyrocal_table::{
    Capabilities, Identity, RateStats, RateTable, RestReport, SettleCriteria, SettleReport,
    StopHandle, TableError, TableState, TableStatus,
};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

/// What the test's event hook asks for.
type Hook = Box<dyn FnMut(&Event) -> Option<StopRequest> + Send>;

/// Runs `plan` on `bench` with `table` (the bench's table driver, maybe wrapped), sending the
/// stop requests `hook` returns for the events it sees. Returns the summary, every event, and
/// the bench.
async fn run_table<T: RateTable + 'static>(
    plan: &Plan,
    dmm: gyrocal_hp34401a::Hp34401aMeter<gyrocal_link::StreamTransport<tokio::io::DuplexStream>>,
    table: T,
    dir: &Path,
    mut hook: Hook,
) -> (RunSummary, Vec<Event>) {
    let (events_tx, mut events) = mpsc::unbounded_channel();
    let mut seq = Sequencer::new(
        plan.clone(),
        dmm,
        table,
        new_run(plan, dir),
        SequencerOptions::default(),
    )
    .with_events(events_tx);
    let (stop_tx, stop_rx) = watch::channel(StopRequest::None);
    let seen = tokio::spawn(async move {
        let mut all = Vec::new();
        while let Some(e) = events.recv().await {
            if let Some(req) = hook(&e) {
                let _ = stop_tx.send(req);
            }
            all.push(e);
        }
        all
    });
    let summary = seq.run(stop_rx).await;
    drop(seq);
    (summary, seen.await.unwrap())
}

async fn run_on_bench(
    plan: &Plan,
    bench: Bench,
    dir: &Path,
    hook: Hook,
) -> (RunSummary, Vec<Event>, BenchHandle) {
    let dmm = common::hp34401a(bench.dmm, plan);
    let table = AclTable::new(bench.table, table_config(plan));
    let (summary, events) = run_table(plan, dmm, table, dir, hook).await;
    (summary, events, bench.handle)
}

/// Asks for a controlled stop once step `step` acquires.
fn stop_when_acquiring(step: usize) -> Hook {
    Box::new(move |e| match e {
        Event::Phase {
            step: s,
            phase: Phase::Acquiring,
        } if *s == step => Some(StopRequest::Controlled("test")),
        _ => None,
    })
}

fn stopping_from(events: &[Event]) -> Option<f64> {
    events.iter().find_map(|e| match e {
        Event::Stopping { from_dps, .. } => *from_dps,
        _ => None,
    })
}

fn rest_event(events: &[Event]) -> Option<&TableRest> {
    events.iter().rev().find_map(|e| match e {
        Event::Rest(r) => Some(r),
        _ => None,
    })
}

#[tokio::test(start_paused = true)]
async fn a_stop_request_ends_the_run_only_once_the_table_is_at_rest() {
    // stopped while acquiring at 20 °/s; at 10 °/s² the deceleration takes 2 s
    let plan = plan_with_rates(&[0.0, 20.0]);
    let tmp = tempfile::tempdir().unwrap();
    let bench = Bench::spawn(bench_config(&plan));
    let (summary, events, bench) = run_on_bench(
        &plan,
        bench,
        &tmp.path().join("run"),
        stop_when_acquiring(1),
    )
    .await;
    // the moment `run` returns, the table is at rest: not decelerating, not turning
    let now = Instant::now();
    let rate = bench.table.actual_rate(now);
    assert!(
        rate.abs() < 0.01,
        "run returned with the table at {rate} °/s"
    );
    assert_eq!(bench.table.mode(), SimMode::Off);
    assert_eq!(summary.status, Status::Aborted);
    assert!(
        summary
            .reason
            .as_deref()
            .unwrap()
            .contains("stopped by test"),
        "{:?}",
        summary.reason
    );
    // the operator was told the deceleration started from ~20 °/s, then rest
    let from = stopping_from(&events).expect("a Stopping event with the rate");
    assert!((from - 20.0).abs() < 0.05, "decelerating from {from}");
    let Some(TableRest::AtRest { waited, .. }) = rest_event(&events) else {
        panic!("no at-rest event: {:?}", rest_event(&events));
    };
    assert!(
        *waited >= Duration::from_millis(1900),
        "a 2 s deceleration waited for only {waited:?}"
    );
    assert!(summary.table.is_at_rest(), "{:?}", summary.table);
    // the interrupted step is not recorded
    assert_eq!(load(&tmp.path().join("run")).unwrap().steps.len(), 1);
}

#[tokio::test(start_paused = true)]
async fn a_second_request_during_the_deceleration_sends_the_emergency_stop() {
    let plan = plan_with_rates(&[0.0, 20.0]);
    let tmp = tempfile::tempdir().unwrap();
    let bench = Bench::spawn(bench_config(&plan));
    let mut first = stop_when_acquiring(1);
    let hook: Hook = Box::new(move |e| match e {
        Event::Stopping { .. } => Some(StopRequest::Emergency("test again")),
        other => first(other),
    });
    let (summary, events, bench) = run_on_bench(&plan, bench, &tmp.path().join("run"), hook).await;
    // the emergency stop opened the interlock; the run still ended with the table at rest
    assert!(
        !bench.table.interlock_closed(),
        "no emergency stop was sent"
    );
    assert!(bench.table.actual_rate(Instant::now()).abs() < 0.01);
    assert!(summary.table.is_at_rest(), "{:?}", summary.table);
    assert_eq!(summary.status, Status::Aborted);
    // the emergency stop cut the 2 s controlled deceleration short (abort profile at the
    // table's 100 °/s² limit)
    let Some(TableRest::AtRest { waited, .. }) = rest_event(&events) else {
        panic!("no at-rest event");
    };
    assert!(*waited < Duration::from_millis(1500), "waited {waited:?}");
}

#[tokio::test(start_paused = true)]
async fn a_table_that_goes_silent_is_never_reported_at_rest() {
    let plan = plan_with_rates(&[0.0, 10.0]);
    let tmp = tempfile::tempdir().unwrap();
    let bench = Bench::spawn(bench_config(&plan));
    // silent halfway through step 1's 50 readings: it keeps turning at 10 °/s
    let spec: gyrocal_sim::faults::FaultSpec = "table:silent@reading75".parse().unwrap();
    let _faults = gyrocal_sim::faults::schedule(&[spec], &bench.handle, 1.0);
    let (summary, events, bench) =
        run_on_bench(&plan, bench, &tmp.path().join("run"), Box::new(|_| None)).await;
    assert_eq!(summary.status, Status::Failed);
    assert!(
        matches!(summary.table, TableRest::NotConfirmed { .. }),
        "{:?}",
        summary.table
    );
    assert!(matches!(
        rest_event(&events),
        Some(TableRest::NotConfirmed { .. })
    ));
    // and that is the truth: the silent table still turns
    assert!((bench.table.actual_rate(Instant::now()) - 10.0).abs() < 0.05);
    assert_eq!(load(&tmp.path().join("run")).unwrap().steps.len(), 1);
}

#[tokio::test(start_paused = true)]
async fn a_table_fault_at_the_end_of_an_acquisition_is_never_recorded() {
    // the fault latches as the last reading of step 1 (readings 51..100) is taken: after the
    // last monitoring sample of the acquisition, before the step would be written
    for spec in ["table:fault@reading100", "table:fault@reading80"] {
        let plan = plan_with_rates(&[0.0, 10.0, -10.0]);
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("run");
        let bench = Bench::spawn(bench_config(&plan));
        let spec_parsed: gyrocal_sim::faults::FaultSpec = spec.parse().unwrap();
        let _faults = gyrocal_sim::faults::schedule(&[spec_parsed], &bench.handle, 1.0);
        let (summary, _, bench) = run_on_bench(&plan, bench, &dir, Box::new(|_| None)).await;
        assert_eq!(summary.status, Status::Failed, "{spec}");
        let reason = summary.reason.unwrap();
        assert!(
            reason.contains("Tracking error limit exceeded"),
            "{spec}: {reason}"
        );
        let steps: Vec<usize> = load(&dir).unwrap().steps.iter().map(|s| s.step).collect();
        assert_eq!(steps, vec![0], "{spec}: step 1 must not be recorded");
        assert!(summary.table.is_at_rest(), "{spec}: {:?}", summary.table);
        assert!(bench.table.actual_rate(Instant::now()).abs() < 0.01);
    }
}

/// What a [`Hooked`] table does to a monitoring sample: given the demand and the number of
/// samples at that demand so far (from 1), the rate to report.
type Perturb = Box<dyn FnMut(f64, usize) -> f64 + Send>;

/// The bench's ACL table with hooks: panics at its `panic_at`-th rate demand (a bug in the
/// sequencer's stack, as far as the run can tell), and passes its monitoring samples through
/// `perturb` (a disturbance the table itself does not report as a fault). It records its own
/// samples, so the sequencer's statistics see the perturbed values.
struct Hooked<T> {
    inner: T,
    demands: usize,
    panic_at: Option<usize>,
    demand: f64,
    at_demand: usize,
    perturb: Perturb,
    recorder: Option<Vec<f64>>,
}

impl<T> Hooked<T> {
    fn new(inner: T) -> Self {
        Hooked {
            inner,
            demands: 0,
            panic_at: None,
            demand: 0.0,
            at_demand: 0,
            perturb: Box::new(|_, _| 0.0),
            recorder: None,
        }
    }
}

impl<T: RateTable> RateTable for Hooked<T> {
    fn describe(&self) -> &str {
        self.inner.describe()
    }
    fn state(&self) -> TableState {
        self.inner.state()
    }
    fn capabilities(&self) -> Capabilities {
        self.inner.capabilities()
    }
    async fn connect(&mut self) -> Result<Identity, TableError> {
        self.inner.connect().await
    }
    async fn enable(&mut self) -> Result<(), TableError> {
        self.inner.enable().await
    }
    async fn set_rate(&mut self, rate: f64, acceleration: f64) -> Result<(), TableError> {
        self.demands += 1;
        self.inner.set_rate(rate, acceleration).await?;
        self.demand = rate;
        self.at_demand = 0;
        assert!(
            Some(self.demands) != self.panic_at,
            "injected panic at demand {}",
            self.demands
        );
        Ok(())
    }
    async fn read_rate(&mut self) -> Result<f64, TableError> {
        self.inner.read_rate().await
    }
    async fn read_position(&mut self) -> Result<f64, TableError> {
        self.inner.read_position().await
    }
    async fn status(&mut self) -> Result<TableStatus, TableError> {
        self.inner.status().await
    }
    async fn sample(&mut self) -> Result<f64, TableError> {
        let rate = self.inner.sample().await?;
        self.at_demand += 1;
        let rate = rate + (self.perturb)(self.demand, self.at_demand);
        if let Some(r) = self.recorder.as_mut() {
            r.push(rate);
        }
        Ok(rate)
    }
    async fn wait_at_rate(
        &mut self,
        criteria: &SettleCriteria,
    ) -> Result<SettleReport, TableError> {
        self.inner.wait_at_rate(criteria).await
    }
    fn start_recording(&mut self) {
        self.recorder = Some(Vec::new());
    }
    fn stop_recording(&mut self) -> RateStats {
        RateStats::from_samples(&self.recorder.take().unwrap_or_default())
    }
    async fn heartbeat(&mut self) -> Result<(), TableError> {
        self.inner.heartbeat().await
    }
    async fn stop(&mut self) -> Result<(), TableError> {
        self.inner.stop().await
    }
    async fn emergency_stop(&mut self) -> Result<(), TableError> {
        self.inner.emergency_stop().await
    }
    async fn wait_stopped(&mut self, timeout: Duration) -> Result<RestReport, TableError> {
        self.inner.wait_stopped(timeout).await
    }
    fn take_retries(&mut self) -> Vec<String> {
        self.inner.take_retries()
    }
    fn stop_handle(&self) -> StopHandle {
        self.inner.stop_handle()
    }
}

/// Runs `plan` on a fresh bench with the table wrapped by `hook`.
async fn run_hooked(
    plan: &Plan,
    dir: &Path,
    hook: impl FnOnce(&mut Hooked<AclTable<gyrocal_link::StreamTransport<tokio::io::DuplexStream>>>),
) -> (RunSummary, BenchHandle) {
    let bench = Bench::spawn(bench_config(plan));
    let dmm = common::hp34401a(bench.dmm, plan);
    let mut table = Hooked::new(AclTable::new(bench.table, table_config(plan)));
    hook(&mut table);
    let (summary, _) = run_table(plan, dmm, table, dir, Box::new(|_| None)).await;
    (summary, bench.handle)
}

#[tokio::test(start_paused = true)]
async fn a_step_the_table_did_not_hold_is_measured_again_once_it_holds() {
    // one sample 0.5 °/s off during step 1's first acquisition (a knock on the table, say):
    // that attempt is thrown away, the step measured again, the run completes
    let plan = plan_with_rates(&[0.0, 10.0, -10.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, bench) = run_hooked(&plan, &dir, |t| {
        let mut bumped = false;
        t.perturb = Box::new(move |demand, k| {
            if demand == 10.0 && k == 3 && !bumped {
                bumped = true;
                0.5
            } else {
                0.0
            }
        });
    })
    .await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let data = load(&dir).unwrap();
    let steps: Vec<usize> = data.steps.iter().map(|s| s.step).collect();
    assert_eq!(steps, vec![0, 1, 2], "every step once");
    // the refused attempt left no samples: exactly one step's worth per step
    let samples = gyrocal_files::load_samples(&dir).unwrap();
    assert_eq!(samples.iter().filter(|s| s.step == 1).count(), 50);
    // the recorded step's table statistics are the clean second attempt's
    let s1 = &data.steps[1];
    assert!(
        (s1.rate_meas_max_dps.unwrap() - 10.0).abs() < 0.005,
        "{s1:?}"
    );
    // and the manifest says what happened
    let retry = data
        .manifest
        .retries
        .iter()
        .find(|r| r.instrument == "table")
        .expect("a table retry in the manifest");
    assert_eq!(retry.step, Some(1));
    assert!(
        retry.message.contains("measuring it again") && retry.message.contains("+10.5"),
        "{}",
        retry.message
    );
    assert!(summary.table.is_at_rest());
    assert!(bench.table.actual_rate(Instant::now()).abs() < 0.01);
}

#[tokio::test(start_paused = true)]
async fn a_table_that_never_holds_the_rate_fails_the_run_without_recording_the_step() {
    // every monitoring sample at 10 °/s is 0.1 °/s off: both attempts are refused (the plan's step 2;
    // messages number steps from 1)
    let plan = plan_with_rates(&[0.0, 10.0, -10.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, bench) = run_hooked(&plan, &dir, |t| {
        t.perturb = Box::new(|demand, _| if demand == 10.0 { 0.1 } else { 0.0 });
    })
    .await;
    assert_eq!(summary.status, Status::Failed);
    let reason = summary.reason.unwrap();
    assert!(
        reason.contains("step 2 at 10 °/s not recorded") && reason.contains("+10.1"),
        "{reason}"
    );
    let data = load(&dir).unwrap();
    assert_eq!(
        data.steps.iter().map(|s| s.step).collect::<Vec<_>>(),
        vec![0]
    );
    assert!(
        gyrocal_files::load_samples(&dir)
            .unwrap()
            .iter()
            .all(|s| s.step == 0)
    );
    assert!(summary.table.is_at_rest());
    assert!(bench.table.actual_rate(Instant::now()).abs() < 0.01);
}

#[tokio::test(start_paused = true)]
async fn a_panic_in_the_sequencer_still_brings_the_table_to_rest() {
    // the panic comes right after the −20 °/s demand was sent: the table is turning at
    // +20 °/s and starts its ramp down
    let plan = plan_with_rates(&[0.0, 20.0, -20.0]);
    let tmp = tempfile::tempdir().unwrap();
    let bench = Bench::spawn(bench_config(&plan));
    let dmm = common::hp34401a(bench.dmm, &plan);
    let mut table = Hooked::new(AclTable::new(bench.table, table_config(&plan)));
    table.panic_at = Some(3);
    let (summary, _) = run_table(
        &plan,
        dmm,
        table,
        &tmp.path().join("run"),
        Box::new(|_| None),
    )
    .await;
    assert_eq!(summary.status, Status::Failed);
    let reason = summary.reason.unwrap();
    assert!(reason.contains("injected panic at demand 3"), "{reason}");
    assert!(summary.table.is_at_rest(), "{:?}", summary.table);
    assert!(bench.handle.table.actual_rate(Instant::now()).abs() < 0.01);
    let m = load(&tmp.path().join("run")).unwrap().manifest;
    assert_eq!(m.status, Status::Failed);
}

/// `plan` on a fresh bench with the fault specs `faults` scheduled; no stop requests.
async fn run_with_faults(plan: &Plan, dir: &Path, faults: &[&str]) -> (RunSummary, BenchHandle) {
    let bench = Bench::spawn(bench_config(plan));
    let specs: Vec<gyrocal_sim::faults::FaultSpec> =
        faults.iter().map(|f| f.parse().unwrap()).collect();
    let _schedule = gyrocal_sim::faults::schedule(&specs, &bench.handle, 1.0);
    let (summary, _, handle) = run_on_bench(plan, bench, dir, Box::new(|_| None)).await;
    (summary, handle)
}

/// Every step of `plan` recorded exactly once with all its samples.
fn assert_every_step_once(plan: &Plan, dir: &Path) {
    let data = load(dir).unwrap();
    let mut steps: Vec<usize> = data.steps.iter().map(|s| s.step).collect();
    steps.sort_unstable();
    let n = plan.schedule().len();
    assert_eq!(steps, (0..n).collect::<Vec<_>>(), "every step exactly once");
    let per = plan.samples_per_rate() as usize;
    let samples = gyrocal_files::load_samples(dir).unwrap();
    for k in 0..n {
        assert_eq!(
            samples.iter().filter(|s| s.step == k).count(),
            per,
            "step {k}"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn a_meter_power_cycle_mid_stream_is_recovered_and_the_run_completes() {
    // the meter is off for 5 s in the middle of step 1's readings, then back in LOCAL with
    // its power-on settings: the driver re-establishes remote mode and the configuration,
    // and takes the lost readings again
    let plan = plan_with_rates(&[0.0, 10.0, -10.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, bench) = run_with_faults(&plan, &dir, &["dmm:powercycle@reading75"]).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_every_step_once(&plan, &dir);
    let m = load(&dir).unwrap().manifest;
    let retry = m
        .retries
        .iter()
        .find(|r| r.instrument == "dmm" && r.step == Some(1))
        .expect("the power cycle is in the manifest");
    assert!(
        retry.message.contains("re-established"),
        "{}",
        retry.message
    );
    // the meter measures at the plan's NPLC again, not its power-on 10 PLC
    let stats = bench.dmm.stats();
    assert_eq!(stats.power_cycles, 1);
    assert_eq!(stats.nplc, 1.0);
    assert!(summary.table.is_at_rest());
}

#[tokio::test(start_paused = true)]
async fn readings_lost_with_the_meters_memory_are_measured_again() {
    // memory mode; the meter power-cycles as the 3rd demand is sent, so step 1's last burst,
    // still in the meter to be fetched during that ramp, is lost: step 1 is measured again
    // after step 2, and the run completes with every step once
    let path = config("quick.toml");
    let mut doc: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    let dmm = doc.get_mut("dmm").unwrap().as_table_mut().unwrap();
    dmm.insert("nplc".into(), toml::Value::Float(0.02));
    dmm.insert("autozero".into(), toml::Value::Boolean(false));
    dmm.insert("acquisition".into(), toml::Value::String("memory".into()));
    let plan = Plan::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, bench) = run_with_faults(&plan, &dir, &["dmm:powercycle@demand3/2s"]).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_every_step_once(&plan, &dir);
    let data = load(&dir).unwrap();
    let order: Vec<usize> = data.steps.iter().map(|s| s.step).collect();
    assert_eq!(
        order,
        vec![0, 2, 1, 3, 4],
        "step 1 measured again after step 2"
    );
    assert!(
        data.manifest
            .retries
            .iter()
            .any(|r| r.step == Some(1) && r.message.contains("measured again after this one")),
        "{:?}",
        data.manifest.retries
    );
    assert_eq!(bench.dmm.stats().power_cycles, 1);
    assert!(summary.table.is_at_rest());
}

#[tokio::test(start_paused = true)]
async fn every_step_is_covered_by_table_samples_over_its_whole_acquisition() {
    // the table is sampled at the start of the acquisition, every 200 ms during it, and once
    // more after the last reading: a step's row counts them
    let plan = plan_with_rates(&[0.0, 10.0, -10.0, 1.0]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _) = run_with_faults(&plan, &dir, &[]).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    let interval = SequencerOptions::default().sample_interval.as_secs_f64();
    for s in load(&dir).unwrap().steps {
        let window = s.t_end_s - s.t_start_s;
        let at_least = (window / interval).floor() as u64 + 1;
        let n = s.rate_samples.expect("rate_samples recorded");
        assert!(
            n >= at_least,
            "step {}: {n} table samples over a {window:.3} s acquisition (want >= {at_least})",
            s.step
        );
        // and every one of them was at the demand
        for v in [s.rate_meas_min_dps.unwrap(), s.rate_meas_max_dps.unwrap()] {
            assert!((v - s.rate_dps).abs() < 0.005, "step {}: {v}", s.step);
        }
    }
}

#[tokio::test(start_paused = true)]
async fn a_retried_fetch_is_counted_once_in_steps_csv_and_the_manifest() {
    // memory mode: step 1's readings are fetched while the table ramps to step 2, and that
    // FETC? reply is garbled once: fetched again after a device clear; the step's row and the
    // manifest count the same one retry
    let path = config("quick.toml");
    let mut doc: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    let dmm = doc.get_mut("dmm").unwrap().as_table_mut().unwrap();
    dmm.insert("nplc".into(), toml::Value::Float(0.02));
    dmm.insert("autozero".into(), toml::Value::Boolean(false));
    dmm.insert("acquisition".into(), toml::Value::String("memory".into()));
    let plan = Plan::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("run");
    let (summary, _) = run_with_faults(&plan, &dir, &["dmm:garble@reading75"]).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_every_step_once(&plan, &dir);
    let data = load(&dir).unwrap();
    for s in &data.steps {
        let logged = data
            .manifest
            .retries
            .iter()
            .filter(|r| r.instrument == "dmm" && r.step == Some(s.step))
            .count() as u32;
        assert_eq!(s.retries, logged, "step {}: steps.csv vs manifest", s.step);
    }
    let s1 = data.steps.iter().find(|s| s.step == 1).unwrap();
    assert_eq!(s1.retries, 1, "{:?}", data.manifest.retries);
}
