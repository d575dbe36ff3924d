//! A temperature series on the simulated meter and table with a FAKE chamber (a `Chamber`
//! whose gyro temperature follows a script of the virtual clock), in virtual time: the series
//! runs, a soak ends exactly when its criterion says, a soak that never settles fails at the
//! maximum wait with a plain message, a chamber alarm mid-sweep stops the run with the table
//! at rest and the step not recorded, a stop request and a panic leave the chamber safe, a
//! silent chamber at the end is "could NOT be confirmed", and a resumed series soaks again
//! where it stopped.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)] // test helpers

mod common;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{new_run, table_config};
use gyrocal_acl::AclTable;
use gyrocal_chamber::{
    Chamber, ChamberError, ChamberIdentity, ChamberMode, ChamberReading, ChamberTiming, SafeReport,
    SafeState,
};
use gyrocal_files::rundir::temps::{Phase, read_temps};
use gyrocal_files::{Plan, RunDir, Status, load};
use gyrocal_run::{
    ChamberRest, Engine, Event, MeterTableChamber, RunSummary, SequencerOptions, StopRequest,
    TableRest,
};
use gyrocal_sim::bench::{Bench, BenchHandle};
use gyrocal_sim::from_plan::bench_config;
use tokio::sync::watch;
use tokio::time::Instant;

/// How the fake chamber's gyro temperature answers: `(seconds since the chamber was made,
/// the setpoint now) -> °C`.
type Response = Box<dyn Fn(f64, f64) -> f64 + Send + Sync>;

/// What the test sees of the fake chamber, and the faults it injects.
#[derive(Default)]
struct Shared {
    /// Every setpoint written, with the time.
    setpoints: Mutex<Vec<(f64, f64)>>,
    /// Every safe state asked for.
    safe: Mutex<Vec<SafeState>>,
    /// Readings report "door open" from now on.
    alarm: AtomicBool,
    /// The controller stops answering (reads and the safe state).
    silent: AtomicBool,
    /// The next read panics (a bug in a driver).
    panic: AtomicBool,
    /// The next this many reads put the gyro 2 °C off.
    excursion: AtomicUsize,
    /// Reads so far.
    reads: AtomicUsize,
}

struct FakeChamber {
    start: Instant,
    setpoint: f64,
    response: Response,
    shared: Arc<Shared>,
}

impl FakeChamber {
    fn new(start_c: f64, response: Response) -> (FakeChamber, Arc<Shared>) {
        let shared = Arc::new(Shared::default());
        (
            FakeChamber {
                start: Instant::now(),
                setpoint: start_c,
                response,
                shared: shared.clone(),
            },
            shared,
        )
    }

    fn t(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    fn silent(&self, request: &str) -> ChamberError {
        ChamberError::Timeout {
            device: "fake chamber".into(),
            request: request.into(),
            timeout_ms: 1000,
        }
    }
}

impl Chamber for FakeChamber {
    fn describe(&self) -> &str {
        "fake chamber"
    }

    async fn connect(&mut self) -> Result<ChamberIdentity, ChamberError> {
        Ok(ChamberIdentity {
            model: "Fake F4".into(),
            detail: "scripted".into(),
        })
    }

    async fn set_setpoint(&mut self, setpoint_c: f64) -> Result<(), ChamberError> {
        if self.shared.silent.load(Ordering::SeqCst) {
            return Err(self.silent("set setpoint"));
        }
        self.setpoint = setpoint_c;
        let t = self.t();
        self.shared.setpoints.lock().unwrap().push((t, setpoint_c));
        Ok(())
    }

    async fn read(&mut self) -> Result<ChamberReading, ChamberError> {
        if self.shared.panic.swap(false, Ordering::SeqCst) {
            panic!("the fake chamber's driver has a bug");
        }
        if self.shared.silent.load(Ordering::SeqCst) {
            return Err(self.silent("read"));
        }
        self.shared.reads.fetch_add(1, Ordering::SeqCst);
        let off = if self
            .shared
            .excursion
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| n.checked_sub(1))
            .is_ok()
        {
            2.0
        } else {
            0.0
        };
        Ok(ChamberReading {
            air_c: self.setpoint,
            product_c: Some((self.response)(self.t(), self.setpoint) + off),
            setpoint_c: self.setpoint,
            mode: ChamberMode::Constant,
            alarms: if self.shared.alarm.load(Ordering::SeqCst) {
                vec!["door open".into()]
            } else {
                Vec::new()
            },
        })
    }

    async fn reset_alarms(&mut self) -> Result<(), ChamberError> {
        self.shared.alarm.store(false, Ordering::SeqCst);
        Ok(())
    }

    async fn go_safe(&mut self, state: SafeState) -> SafeReport {
        self.shared.safe.lock().unwrap().push(state);
        if self.shared.silent.load(Ordering::SeqCst) {
            return SafeReport {
                state,
                confirmed: false,
                detail: "no answer to the setpoint's read-back within 1000 ms".into(),
            };
        }
        if let SafeState::Ambient { setpoint_c } = state {
            self.setpoint = setpoint_c;
        }
        SafeReport {
            state,
            confirmed: true,
            detail: format!("setpoint read back {} °C, constant", self.setpoint),
        }
    }

    fn timing(&self) -> ChamberTiming {
        ChamberTiming {
            read: Duration::ZERO,
            reply_timeout: Duration::from_secs(1),
        }
    }
}

/// The gyro follows the setpoint at once (a chamber and gyro with no lag).
fn no_lag() -> Response {
    Box::new(|_, sp| sp)
}

/// A short series: quick.toml's bench, rates [0, 5, -5], 20 readings, `temps` with a soak of
/// `soak_min`, polls of 10 s, a ramp of 5 °C/min, `max_wait_min`.
fn series(temps: &str, soak_min: f64, max_wait_min: f64) -> Plan {
    let quick = std::fs::read_to_string(common::config("quick.toml")).unwrap();
    let mut doc: toml::Table = quick.parse().unwrap();
    let p = doc.get_mut("plan").unwrap().as_table_mut().unwrap();
    p.insert("kind".into(), "temperature_series".into());
    p.insert(
        "rates_dps".into(),
        toml::Value::Array(vec![0.0.into(), 5.0.into(), (-5.0).into()]),
    );
    p.insert("samples_per_rate".into(), 20.into());
    let text = format!(
        "{}\n[series]\ntemperatures_c = {temps}\nmeasure = \"sweep\"\nband_c = 0.5\n\
         stability_c_per_min = 0.05\nsoak_min = {soak_min}\nmax_wait_min = {max_wait_min}\n\
         poll_s = 10\n[chamber]\nmodel = \"watlow_f4\"\nport = \"/dev/ttyUSB2\"\n\
         ramp_c_per_min = 5\nambient_c = 23\n",
        toml::to_string(&doc).unwrap()
    );
    Plan::from_toml_str(&text, Path::new("series.toml")).unwrap()
}

/// A test's series: its plan (see [`series`]) and the run directory it writes.
struct Case {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
    plan: Plan,
}

impl Case {
    fn new(temps: &str, soak_min: f64, max_wait_min: f64) -> Case {
        let tmp = tempfile::tempdir().unwrap();
        Case {
            dir: tmp.path().join("run"),
            _tmp: tmp,
            plan: series(temps, soak_min, max_wait_min),
        }
    }

    /// Runs the series on a new run directory with a fake chamber at `start_c` whose gyro
    /// answers `response`; `on_step(done, shared, stop)` is called after each step recorded.
    async fn run(
        &self,
        start_c: f64,
        response: Response,
        on_step: impl FnMut(usize, &Shared, &watch::Sender<StopRequest>) + Send + 'static,
    ) -> (RunSummary, BenchHandle, Arc<Shared>) {
        self.run_events(start_c, response, after_each_step(on_step))
            .await
    }

    /// [`Case::run`] with `on_event(event, shared, stop)` called for every event.
    async fn run_events(
        &self,
        start_c: f64,
        response: Response,
        on_event: impl FnMut(&Event, &Shared, &watch::Sender<StopRequest>) + Send + 'static,
    ) -> (RunSummary, BenchHandle, Arc<Shared>) {
        let (chamber, shared) = FakeChamber::new(start_c, response);
        let run = new_run(&self.plan, &self.dir);
        let (summary, handle) = run_series(&self.plan, run, chamber, on_event).await;
        (summary, handle, shared)
    }

    /// Resumes the series in its run directory with a fake chamber back at ambient (23 °C)
    /// whose gyro has no lag.
    async fn resume(&self) -> (RunSummary, BenchHandle, Arc<Shared>) {
        let (chamber, shared) = FakeChamber::new(23.0, no_lag());
        let run = RunDir::open_for_resume(&self.dir, &self.plan).unwrap();
        let (summary, handle) = run_series(&self.plan, run, chamber, |_, _, _| {}).await;
        (summary, handle, shared)
    }
}

/// `fault(shared, stop)` once the `n`th step is recorded.
fn at_step(
    n: usize,
    fault: impl Fn(&Shared, &watch::Sender<StopRequest>) + Send + 'static,
) -> impl FnMut(usize, &Shared, &watch::Sender<StopRequest>) + Send + 'static {
    move |done, shared, stop| {
        if done == n {
            fault(shared, stop);
        }
    }
}

/// A controlled stop, as SIGINT asks.
fn sigint(_: &Shared, stop: &watch::Sender<StopRequest>) {
    let _ = stop.send(StopRequest::Controlled("SIGINT"));
}

/// `on_step(done, shared, stop)` called after each step recorded, as an event handler.
fn after_each_step(
    mut on_step: impl FnMut(usize, &Shared, &watch::Sender<StopRequest>) + Send + 'static,
) -> impl FnMut(&Event, &Shared, &watch::Sender<StopRequest>) + Send + 'static {
    let mut done = 0;
    move |e, shared, stop| {
        if matches!(e, Event::StepDone(_)) {
            done += 1;
            on_step(done, shared, stop);
        }
    }
}

/// Runs `plan` on a fresh simulated meter and table and `chamber`, writing to `run`;
/// `on_event(event, shared, stop)` is called for every event.
async fn run_series(
    plan: &Plan,
    run: RunDir,
    chamber: FakeChamber,
    mut on_event: impl FnMut(&Event, &Shared, &watch::Sender<StopRequest>) + Send + 'static,
) -> (RunSummary, BenchHandle) {
    let bench = Bench::spawn(bench_config(plan));
    let handle = bench.handle;
    let shared = chamber.shared.clone();
    let dmm = common::hp34401a(bench.dmm, plan);
    let table = AclTable::new(bench.table, table_config(plan));
    let (events_tx, mut events) = tokio::sync::mpsc::unbounded_channel();
    let mut engine = Engine::on_bench(
        plan.clone(),
        MeterTableChamber::new(dmm, table, chamber),
        run,
        SequencerOptions::default(),
    )
    .with_events(events_tx);
    let (stop_tx, stop_rx) = watch::channel(StopRequest::None);
    tokio::spawn(async move {
        while let Some(e) = events.recv().await {
            on_event(&e, &shared, &stop_tx);
        }
    });
    let summary = engine.run(stop_rx).await;
    (summary, handle)
}

fn assert_table_at_rest(summary: &RunSummary, handle: &BenchHandle) {
    assert!(
        matches!(summary.table, TableRest::AtRest { .. }),
        "{:?}",
        summary.table
    );
    assert!(handle.table.is_stopped(), "the simulated table still turns");
}

/// The table at rest and the chamber confirmed in its safe state.
fn assert_both_safe(summary: &RunSummary, handle: &BenchHandle, shared: &Shared) {
    assert_table_at_rest(summary, handle);
    assert_chamber_safe(summary, shared);
}

fn assert_chamber_safe(summary: &RunSummary, shared: &Shared) {
    assert_eq!(
        summary.chamber.line().as_deref(),
        Some("chamber: setpoint 23 °C (ambient), in control: confirmed"),
        "{:?}",
        summary.chamber
    );
    assert_eq!(
        shared.safe.lock().unwrap().as_slice(),
        [SafeState::Ambient { setpoint_c: 23.0 }]
    );
}

#[tokio::test(start_paused = true)]
async fn a_series_runs_soaking_and_sweeping_at_each_temperature_and_ends_safe() {
    let c = Case::new("[25, -20, 25]", 2.0, 60.0);
    let (summary, handle, shared) = c.run(23.0, no_lag(), |_, _, _| {}).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_eq!(summary.reason, None);
    assert_both_safe(&summary, &handle, &shared);
    let data = load(&c.dir).unwrap();
    assert_eq!(data.steps.len(), 9);
    for (i, s) in data.steps.iter().enumerate() {
        let c = s.series.unwrap();
        assert_eq!(c.series_point as usize, i / 3);
        assert_eq!(c.setpoint_c, [25.0, -20.0, 25.0][i / 3]);
        // the gyro sat on the setpoint: its min/mean/max during the step say so
        assert_eq!(
            (c.temp_min_c, c.temp_mean_c, c.temp_max_c),
            (Some(c.setpoint_c), Some(c.setpoint_c), Some(c.setpoint_c))
        );
        assert!(!c.bias_record);
    }
    // the chamber was ramped at 5 °C/min: 25 → -20 is 45 °C, 9 minutes of polls of 10 s,
    // never a step larger than 5/6 °C
    let setpoints = shared.setpoints.lock().unwrap().clone();
    for w in setpoints.windows(2) {
        assert!((w[1].1 - w[0].1).abs() <= 5.0 / 6.0 + 1e-9, "{w:?}");
    }
    assert!(setpoints.iter().any(|(_, s)| *s == -20.0));
    // temps.csv: every phase, each row at its point
    let temps = read_temps(&c.dir).unwrap();
    for phase in [Phase::Ramp, Phase::Soak, Phase::Measure, Phase::Safe] {
        assert!(temps.iter().any(|r| r.phase == phase), "{phase:?}");
    }
    assert!(temps.windows(2).all(|w| w[0].t_s <= w[1].t_s));
    assert_eq!(temps.last().unwrap().phase, Phase::Safe);
    assert_eq!(temps.last().unwrap().setpoint_c, 23.0);
    let m = load(&c.dir).unwrap().manifest;
    let c = m.chamber.unwrap();
    assert_eq!(c.safe_confirmed, Some(true));
    assert!(c.identity.unwrap().contains("Fake F4"));
    assert!(m.checksums.contains_key("temps.csv"));
}

/// The gyro is 3 °C off the target until 600 s after the chamber is made, then on it: the
/// criterion holds once the 5-minute slope window has only readings on the target (900 s),
/// and the soak of 5 minutes ends at the reading 300 s later, 1200 s after it began.
#[tokio::test(start_paused = true)]
async fn a_soak_ends_exactly_when_its_criterion_has_held_for_the_soak_time() {
    let c = Case::new("[25]", 5.0, 60.0);
    // the chamber starts at the target: no ramp
    let (summary, _, shared) = c
        .run(
            25.0,
            Box::new(|t, sp| if t < 600.0 { sp + 3.0 } else { sp }),
            |_, _, _| {},
        )
        .await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_chamber_safe(&summary, &shared);
    let temps = read_temps(&c.dir).unwrap();
    let first = temps.first().unwrap();
    let soaking: Vec<_> = temps
        .iter()
        .filter(|r| matches!(r.phase, Phase::Ramp | Phase::Soak))
        .collect();
    let last = soaking.last().unwrap();
    assert!(
        (last.t_s - first.t_s - 1200.0).abs() < 1e-6,
        "{first:?} .. {last:?}"
    );
    // a reading every 10 s
    assert_eq!(soaking.len(), 121);
}

#[tokio::test(start_paused = true)]
async fn a_soak_that_never_settles_fails_plainly_at_the_maximum_wait() {
    let c = Case::new("[25, -20]", 2.0, 20.0);
    let (summary, handle, shared) = c.run(25.0, Box::new(|_, sp| sp + 3.0), |_, _, _| {}).await;
    assert_eq!(summary.status, Status::Failed);
    let reason = summary.reason.clone().unwrap();
    assert_eq!(
        reason,
        "temperature 1 of the series (25 °C) not soaked after 20.0 min (max_wait_min): the gyro \
         read 28 °C (band ±0.5 °C, changing 0.000 °C/min, limit 0.05 °C/min); check the chamber \
         and the gyro's sensor, or widen the band or the wait"
    );
    assert!(summary.resumable);
    assert_eq!(summary.steps_recorded, 0);
    assert_both_safe(&summary, &handle, &shared);
    // 20 minutes of polls of 10 s
    let temps = read_temps(&c.dir).unwrap();
    let soak: Vec<_> = temps.iter().filter(|r| r.phase != Phase::Safe).collect();
    assert!((soak.last().unwrap().t_s - soak[0].t_s - 1200.0).abs() < 1e-6);
}

#[tokio::test(start_paused = true)]
async fn a_chamber_alarm_mid_sweep_stops_with_the_table_at_rest_and_the_step_not_recorded() {
    let c = Case::new("[25, -20]", 1.0, 60.0);
    // the door opens once the 4th step (the first at -20 °C) is recorded
    let door = at_step(4, |s, _| s.alarm.store(true, Ordering::SeqCst));
    let (summary, handle, shared) = c.run(25.0, no_lag(), door).await;
    assert_eq!(summary.status, Status::Failed);
    let reason = summary.reason.clone().unwrap();
    assert!(
        reason.starts_with("chamber alarm: door open during step 5, which is not recorded"),
        "{reason}"
    );
    assert!(summary.resumable);
    assert_table_at_rest(&summary, &handle);
    // the alarm does not keep the chamber from its safe state
    assert_eq!(shared.safe.lock().unwrap().len(), 1);
    let data = load(&c.dir).unwrap();
    assert_eq!(data.steps.len(), 4);
    assert_eq!(data.manifest.status, Status::Failed);
}

#[tokio::test(start_paused = true)]
async fn a_stop_request_mid_sweep_leaves_the_chamber_safe() {
    let c = Case::new("[25, -20]", 1.0, 60.0);
    let (summary, handle, shared) = c.run(25.0, no_lag(), at_step(2, sigint)).await;
    assert_eq!(summary.status, Status::Aborted);
    assert_both_safe(&summary, &handle, &shared);
}

#[tokio::test(start_paused = true)]
async fn a_panic_in_the_chambers_driver_still_leaves_both_machines_safe() {
    let c = Case::new("[25, -20]", 1.0, 60.0);
    let bug = at_step(1, |s, _| s.panic.store(true, Ordering::SeqCst));
    let (summary, handle, shared) = c.run(25.0, no_lag(), bug).await;
    assert_eq!(summary.status, Status::Failed);
    assert!(
        summary.reason.clone().unwrap().contains("panic"),
        "{:?}",
        summary.reason
    );
    assert_both_safe(&summary, &handle, &shared);
}

#[tokio::test(start_paused = true)]
async fn a_silent_chamber_at_the_end_is_said_could_not_be_confirmed() {
    let c = Case::new("[25]", 1.0, 60.0);
    let silent = at_step(3, |s, _| s.silent.store(true, Ordering::SeqCst));
    let (summary, handle, _) = c.run(25.0, no_lag(), silent).await;
    // the data are complete; the chamber's state is not
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_table_at_rest(&summary, &handle);
    assert!(!summary.chamber.is_safe());
    let line = summary.chamber.line().unwrap();
    assert_eq!(
        line,
        "chamber: setpoint 23 °C (ambient), in control could NOT be confirmed: no answer to the \
         setpoint's read-back within 1000 ms; check the chamber by hand"
    );
    assert!(
        summary
            .reason
            .clone()
            .unwrap()
            .contains("could NOT be confirmed"),
        "{:?}",
        summary.reason
    );
    let m = load(&c.dir).unwrap().manifest;
    assert_eq!(m.chamber.unwrap().safe_confirmed, Some(false));
}

#[tokio::test(start_paused = true)]
async fn a_step_whose_gyro_left_the_band_is_measured_again() {
    let c = Case::new("[25]", 1.0, 60.0);
    // the next reading (the 2nd step's) is 2 °C off
    let excursion = at_step(1, |s, _| s.excursion.store(1, Ordering::SeqCst));
    let (summary, _, shared) = c.run(25.0, no_lag(), excursion).await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_chamber_safe(&summary, &shared);
    let data = load(&c.dir).unwrap();
    assert_eq!(data.steps.len(), 3);
    // recorded in band; the refusal is in the manifest
    assert_eq!(data.steps[1].series.unwrap().temp_max_c, Some(25.0));
    let retry = data
        .manifest
        .retries
        .iter()
        .find(|r| r.instrument == "chamber")
        .unwrap();
    assert_eq!(retry.step, Some(1));
    assert!(
        retry.message.contains("left the band") && retry.message.contains("27 °C"),
        "{}",
        retry.message
    );
    let temps = read_temps(&c.dir).unwrap();
    assert!(
        temps
            .iter()
            .any(|r| r.phase == Phase::Measure && r.product_c == Some(27.0))
    );
}

#[tokio::test(start_paused = true)]
async fn a_resumed_series_soaks_again_at_the_temperature_where_it_stopped() {
    let c = Case::new("[25, -20, 25]", 1.0, 60.0);
    // stopped after the first step at -20 °C
    let (summary, _, _) = c.run(23.0, no_lag(), at_step(4, sigint)).await;
    assert_eq!(summary.status, Status::Aborted);
    let before = read_temps(&c.dir).unwrap().len();
    // the chamber went back to ambient meanwhile
    let (summary, handle, shared) = c.resume().await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_both_safe(&summary, &handle, &shared);
    // the second session's first readings ramp and soak at -20 °C (point 1) before measuring
    let temps = read_temps(&c.dir).unwrap();
    let session2 = &temps[before..];
    assert_eq!(session2[0].phase, Phase::Ramp);
    assert_eq!(session2[0].series_point, Some(1));
    let first_measure = session2
        .iter()
        .position(|r| r.phase == Phase::Measure)
        .unwrap();
    assert!(
        session2[..first_measure]
            .iter()
            .any(|r| r.phase == Phase::Soak && r.setpoint_c == -20.0)
    );
    // the chamber was driven from ambient to -20 °C again
    let setpoints = shared.setpoints.lock().unwrap().clone();
    assert!(setpoints[0].1 > 20.0 && setpoints.iter().any(|s| s.1 == -20.0));
    let data = load(&c.dir).unwrap();
    assert_eq!(data.steps.len(), 9);
    let points: Vec<u32> = data
        .steps
        .iter()
        .map(|s| s.series.unwrap().series_point)
        .collect();
    assert_eq!(points, [0, 0, 0, 1, 1, 1, 2, 2, 2]);
}

#[tokio::test(start_paused = true)]
async fn a_series_on_a_bench_without_a_chamber_is_refused_before_anything_moves() {
    let c = Case::new("[25]", 1.0, 60.0);
    let bench = Bench::spawn(bench_config(&c.plan));
    let dmm = common::hp34401a(bench.dmm, &c.plan);
    let table = AclTable::new(bench.table, table_config(&c.plan));
    let mut seq = gyrocal_run::Sequencer::new(
        c.plan.clone(),
        dmm,
        table,
        new_run(&c.plan, &c.dir),
        SequencerOptions::default(),
    );
    let (_stop_tx, stop_rx) = watch::channel(StopRequest::None);
    let summary = seq.run(stop_rx).await;
    assert_eq!(summary.status, Status::Failed);
    assert!(
        summary
            .reason
            .clone()
            .unwrap()
            .contains("this bench has no chamber"),
        "{:?}",
        summary.reason
    );
    assert_eq!(summary.steps_recorded, 0);
    // the plan's chamber was never reached: not "confirmed" by a bench that has none
    assert!(
        matches!(&summary.chamber, ChamberRest::NotConfirmed { reason, .. } if reason.contains("never reached")),
        "{:?}",
        summary.chamber
    );
}

#[tokio::test(start_paused = true)]
async fn a_series_stopped_mid_soak_soaks_again_when_resumed() {
    let c = Case::new("[25, -20]", 1.0, 60.0);
    // SIGINT two minutes into the soak at -20 °C (mid-ramp)
    let two_minutes_in = |e: &Event, s: &Shared, stop: &watch::Sender<StopRequest>| {
        if let Event::Soak {
            point: 1, waited, ..
        } = e
            && *waited >= Duration::from_secs(120)
        {
            sigint(s, stop);
        }
    };
    let (summary, _, shared) = c.run_events(23.0, no_lag(), two_minutes_in).await;
    assert_eq!(summary.status, Status::Aborted);
    assert_chamber_safe(&summary, &shared);
    assert_eq!(load(&c.dir).unwrap().steps.len(), 3);
    let before = read_temps(&c.dir).unwrap().len();
    let (summary, _, shared) = c.resume().await;
    assert_eq!(summary.status, Status::Complete, "{:?}", summary.reason);
    assert_chamber_safe(&summary, &shared);
    let temps = read_temps(&c.dir).unwrap();
    // the resumed session ramps from ambient to -20 °C again and soaks before measuring
    let session2 = &temps[before..];
    assert_eq!(
        (session2[0].phase, session2[0].series_point),
        (Phase::Ramp, Some(1))
    );
    let first_measure = session2
        .iter()
        .position(|r| r.phase == Phase::Measure)
        .unwrap();
    assert!(
        session2[..first_measure]
            .iter()
            .any(|r| r.phase == Phase::Soak && r.setpoint_c == -20.0)
    );
    assert_eq!(load(&c.dir).unwrap().steps.len(), 6);
}
