//! The live state a run publishes for viewers (`gyrocal serve`): a small `live.json` in the
//! run directory, replaced atomically (a temporary file renamed over it, so a reader sees the
//! old state or the new, never half of one).
//!
//! Why a file and not a socket: the run directory stays the truth, and a web view that is
//! slow, stopped or crashed must cost the run nothing. The sink only updates a state in memory
//! (a mutex held for a few field writes) and, at most every [`MIN_INTERVAL`] of wall time and
//! at each step's end, wakes a writer thread of its own without waiting for it (a full
//! one-slot channel means a write is already due). No fsync: after a crash the file may be
//! one update behind, which a viewer shows as stale anyway (`pid`, `hostname`,
//! `updated_utc`).
//!
//! Bounded: the state holds one summary per recorded step (a run's step count), never its
//! readings, so a 24-hour record's file stays small.
//!
//! A failure to write it is a note in the log (once), never a run failure: every [`Sink`]
//! method returns `Ok`.
//!
//! Two more readers may follow the state: a [`Publisher`] ([`LiveFile::with_publisher`]) is
//! handed each state written (the CLI's is the catalog's message bus, which must not block:
//! it only swaps the state into a one-slot mailbox), and the [`LiveHandle`] lets the end of
//! the run add what only the analysis after it knows (the verdict, [`LiveHandle::conclude`]).
//! A temperature series' soak shows as phase `soaking` with the gyro's temperature and the
//! chamber's setpoint (`chamber`, a member added in format 1: older readers ignore it).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::engine::{Event, Phase, TableRest};
use crate::sink::{Connected, Finish, LiveFn, Recorded, Sink, SinkError};
use gyrocal_files::rundir::Status;

/// The live state's file name in the run directory.
pub const LIVE_JSON: &str = "live.json";

/// The least wall time between two writes of `live.json` (a step's end and the run's end are
/// written whenever they happen).
pub const MIN_INTERVAL: Duration = Duration::from_millis(500);

/// The format of `live.json` (bumped when a member changes meaning).
pub const LIVE_FORMAT: u32 = 1;

/// One recorded step, as a viewer's table and plot show it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepSummary {
    /// 1-based step number (steps.csv's `step_no`).
    pub number: usize,
    /// Commanded rate, °/s.
    pub rate_dps: f64,
    /// Mean output, V.
    pub volts: f64,
    /// Standard deviation of the readings, V.
    pub volts_std: Option<f64>,
    /// Valid readings.
    pub n: u64,
    /// Overloaded readings left out.
    pub overloads: u64,
    /// The run clock at the end of the acquisition, s.
    pub t_end_s: f64,
}

/// A temperature series' chamber in the live state (the last reading of a soak).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveChamber {
    /// The gyro's temperature (the chamber's product sensor, else its air), °C.
    pub temperature_c: Option<f64>,
    /// The chamber's setpoint now (moving towards the target during the soak's ramp), °C.
    pub setpoint_c: Option<f64>,
    /// The soak's target, °C.
    pub target_c: Option<f64>,
}

/// What `live.json` holds (every member is what a viewer shows; see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LiveState {
    /// [`LIVE_FORMAT`].
    pub format: u32,
    /// The run's id (the run directory's name).
    pub run_id: String,
    /// The station's id, when the run has a station file.
    pub station: Option<String>,
    /// The gyro's serial number.
    pub gyro_serial: Option<String>,
    /// The plan's name.
    pub plan_name: String,
    /// The plan's kind (`scale_factor`, `drift`, ...).
    pub plan_kind: String,
    /// `connecting`, `ramping`, `settling`, `acquiring`, `recording` (a drift record's
    /// segment), `soaking`, `ending`, `done`, `aborted` or `failed`.
    pub phase: String,
    /// The step under way (1-based; the last recorded one between steps), 0 before the first.
    pub step: usize,
    /// Steps in the plan's schedule.
    pub steps: usize,
    /// Steps recorded so far (this session's and earlier sessions').
    pub steps_done: usize,
    /// Estimated time to the end, s (from the instruments' timing models).
    pub eta_s: Option<f64>,
    /// The last reading, V.
    pub last_reading_v: Option<f64>,
    /// The running mean of the current acquisition, V.
    pub running_mean_v: Option<f64>,
    /// The table: its demanded and measured rate while waiting for a rate, its end state.
    pub table: Option<String>,
    /// The steps recorded in this session, in order.
    pub step_summaries: Vec<StepSummary>,
    /// `running`, `complete`, `aborted` or `failed`.
    pub status: String,
    /// Why the run failed or was aborted.
    pub reason: Option<String>,
    /// The acceptance verdict (`pass`, `marginal`, `indeterminate`, `fail`) once the analysis
    /// after the run knows it: the last state written carries it ([`LiveHandle::conclude`]).
    pub verdict: Option<String>,
    /// A temperature series' chamber: the last reading of its soak (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber: Option<LiveChamber>,
    /// A drift record's running overlapping Allan deviation, `(τ s, σ V)` at every octave τ
    /// up to 100 s of this session's readings (the streaming accumulator's figures: a dozen
    /// points whatever the record's length); empty otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub adev_v: Vec<(f64, f64)>,
    /// When the run started (its first session), RFC 3339 UTC, as in its manifest: a view
    /// that knows the run only through the catalog shows it (absent in older files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub started_utc: Option<String>,
    /// When the run ended, RFC 3339 UTC, once it has: the wall clock at its end, or in virtual
    /// time `started_utc` plus the run clock (the manifest's rule; absent while running).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended_utc: Option<String>,
    /// The process writing this file.
    pub pid: u32,
    /// The host it runs on.
    pub hostname: String,
    /// When this state was written, RFC 3339 UTC.
    pub updated_utc: String,
}

/// What the run's identity is, for the live state.
#[derive(Debug, Clone, Default)]
pub struct LiveHeader {
    /// See [`LiveState::run_id`].
    pub run_id: String,
    /// See [`LiveState::station`].
    pub station: Option<String>,
    /// See [`LiveState::gyro_serial`].
    pub gyro_serial: Option<String>,
    /// See [`LiveState::plan_name`].
    pub plan_name: String,
    /// See [`LiveState::plan_kind`].
    pub plan_kind: String,
    /// See [`LiveState::steps`].
    pub steps: usize,
    /// Steps already recorded (a resumed run).
    pub steps_done: usize,
    /// See [`LiveState::started_utc`].
    pub started_utc: Option<String>,
    /// The run's stamps are on the run clock (a simulated run in virtual time): its end is
    /// `started_utc` plus the run clock, not the wall clock.
    pub virtual_time: bool,
}

impl LiveHeader {
    /// The header of the run in `run` (its manifest's plan, gyro and station).
    pub fn of(run: &gyrocal_files::rundir::RunDir) -> LiveHeader {
        let m = run.manifest();
        LiveHeader {
            run_id: run
                .path()
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            station: m.station.as_ref().map(|s| s.id.clone()),
            gyro_serial: m.dut.as_ref().and_then(|d| d.serial.clone()),
            plan_name: m.plan.name().to_string(),
            plan_kind: m.plan.kind().as_str().to_string(),
            steps: m.steps_total,
            steps_done: m.steps_done.len(),
            started_utc: Some(m.started_utc.clone()),
            virtual_time: m.virtual_time,
        }
    }
}

/// The state in memory and when it was last handed to the writer.
struct Shared {
    state: LiveState,
    /// `remaining` and `after` of the last step start, and when it came (wall time): the ETA
    /// counts down within the step.
    eta: Option<(Duration, Duration, Instant)>,
    last_sent: Option<Instant>,
    /// [`LiveHeader::virtual_time`].
    virtual_time: bool,
}

impl Shared {
    fn snapshot(&self) -> LiveState {
        let mut s = self.state.clone();
        if let Some((remaining, after, at)) = self.eta {
            let left = remaining.saturating_sub(at.elapsed()).max(after);
            s.eta_s = Some(left.as_secs_f64());
        }
        s.updated_utc = gyrocal_files::rfc3339_utc(std::time::SystemTime::now());
        s
    }
}

/// Who else is handed each live state written (see the module docs): it must return at once.
pub type Publisher = Arc<dyn Fn(&LiveState) + Send + Sync>;

/// The sink that keeps `live.json` (see the module docs).
pub struct LiveFile {
    path: PathBuf,
    publisher: Arc<Mutex<Option<Publisher>>>,
    shared: Arc<Mutex<Shared>>,
    wake: Option<SyncSender<()>>,
    /// Tells the writer thread to end (with a wake, so it sees it).
    stop: Arc<AtomicBool>,
    writer: Option<std::thread::JoinHandle<()>>,
}

fn lock(m: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    // a panic while holding it leaves only a field half updated: keep publishing
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Writes `state` to `path` through a temporary file beside it, renamed over it.
pub fn write_live(path: &Path, state: &LiveState) -> std::io::Result<()> {
    let bytes = serde_json::to_vec_pretty(state).map_err(std::io::Error::other)?;
    let tmp = gyrocal_files::atomic::temp_path(path);
    let r = std::fs::write(&tmp, &bytes).and_then(|()| std::fs::rename(&tmp, path));
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

fn phase_name(phase: Phase, drift: bool) -> &'static str {
    match phase {
        Phase::Ramping => "ramping",
        Phase::Settling => "settling",
        Phase::Acquiring | Phase::Fetching if drift => "recording",
        Phase::Acquiring | Phase::Fetching => "acquiring",
    }
}

impl LiveFile {
    /// The live state of a run in `dir` (written to `dir/live.json` from now on, by a
    /// thread of its own).
    pub fn new(dir: &Path, header: LiveHeader) -> LiveFile {
        let path = dir.join(LIVE_JSON);
        let state = LiveState {
            format: LIVE_FORMAT,
            run_id: header.run_id,
            station: header.station,
            gyro_serial: header.gyro_serial,
            plan_name: header.plan_name,
            plan_kind: header.plan_kind,
            phase: "connecting".into(),
            step: header.steps_done,
            steps: header.steps,
            steps_done: header.steps_done,
            eta_s: None,
            last_reading_v: None,
            running_mean_v: None,
            table: None,
            step_summaries: Vec::new(),
            status: "running".into(),
            reason: None,
            verdict: None,
            chamber: None,
            adev_v: Vec::new(),
            started_utc: header.started_utc,
            ended_utc: None,
            pid: std::process::id(),
            hostname: gyrocal_files::rundir::host_name(),
            updated_utc: String::new(),
        };
        let shared = Arc::new(Mutex::new(Shared {
            state,
            eta: None,
            last_sent: None,
            virtual_time: header.virtual_time,
        }));
        let publisher: Arc<Mutex<Option<Publisher>>> = Arc::new(Mutex::new(None));
        let (tx, rx) = mpsc::sync_channel::<()>(1);
        // the writer ends on this flag, not on the channel closing: the live closure handed
        // to the engine's monitors holds a sender too, and while it lives the channel stays
        // open (joining on the channel alone hung every run at its end)
        let stop = Arc::new(AtomicBool::new(false));
        let writer = {
            let shared = shared.clone();
            let path = path.clone();
            let stop = stop.clone();
            let publisher = publisher.clone();
            std::thread::Builder::new()
                .name("live.json".into())
                .spawn(move || {
                    let mut noted = false;
                    while rx.recv().is_ok() && !stop.load(Ordering::Acquire) {
                        let snap = lock(&shared).snapshot();
                        publish(&publisher, &snap);
                        if let Err(e) = write_live(&path, &snap)
                            && !std::mem::replace(&mut noted, true)
                        {
                            tracing::warn!(
                                "{}: cannot write the live state ({e}); the run goes on \
                                 without it",
                                path.display()
                            );
                        }
                    }
                })
                .ok()
        };
        let live = LiveFile {
            stop,
            path,
            publisher,
            shared,
            wake: writer.as_ref().map(|_| tx),
            writer,
        };
        live.poke(true);
        live
    }

    /// Hands every state written from now on to `publisher` too (it must return at once).
    pub fn with_publisher(self, publisher: Publisher) -> LiveFile {
        *self
            .publisher
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(publisher);
        // the state so far, at once
        self.poke(true);
        self
    }

    /// A handle for the end of the run (see [`LiveHandle::conclude`]).
    pub fn handle(&self) -> LiveHandle {
        LiveHandle {
            path: self.path.clone(),
            shared: self.shared.clone(),
            publisher: self.publisher.clone(),
        }
    }

    /// Asks the writer for a write when one is due (`force`: a step's end), never waiting.
    fn poke(&self, force: bool) {
        poke(&self.shared, self.wake.as_ref(), force);
    }

    fn update(&self, force: bool, f: impl FnOnce(&mut Shared)) {
        f(&mut lock(&self.shared));
        self.poke(force);
    }
}

/// A state written outside the writer thread (the run's end, its verdict): handed to the
/// publisher and written to `path`; a failed write is warned (`then` says what still holds),
/// never an error of the run.
fn deliver(publisher: &Mutex<Option<Publisher>>, path: &Path, state: &LiveState, then: &str) {
    publish(publisher, state);
    if let Err(e) = write_live(path, state) {
        tracing::warn!(
            "{}: cannot write the live state ({e}); {then}",
            path.display()
        );
    }
}

fn publish(publisher: &Mutex<Option<Publisher>>, state: &LiveState) {
    let p = publisher
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone();
    if let Some(p) = p {
        p(state);
    }
}

/// What the end of a run adds to its live state after the sinks are done: the verdict the
/// analysis found. Cheap to clone; each call writes the file at once (the run is over).
#[derive(Clone)]
pub struct LiveHandle {
    path: PathBuf,
    shared: Arc<Mutex<Shared>>,
    publisher: Arc<Mutex<Option<Publisher>>>,
}

impl LiveHandle {
    /// Sets the verdict (when known) and writes the state a last time, and publishes it. A
    /// failure to write is a note in the log.
    pub fn conclude(&self, verdict: Option<&str>) {
        let snap = {
            let mut s = lock(&self.shared);
            if let Some(v) = verdict {
                s.state.verdict = Some(v.to_string());
            }
            s.snapshot()
        };
        deliver(
            &self.publisher,
            &self.path,
            &snap,
            "its verdict is in the manifest",
        );
    }

    /// The state as it is now.
    pub fn state(&self) -> LiveState {
        lock(&self.shared).snapshot()
    }
}

fn poke(shared: &Mutex<Shared>, wake: Option<&SyncSender<()>>, force: bool) {
    let Some(wake) = wake else { return };
    {
        let mut s = lock(shared);
        if !force && s.last_sent.is_some_and(|t| t.elapsed() < MIN_INTERVAL) {
            return;
        }
        s.last_sent = Some(Instant::now());
    }
    match wake.try_send(()) {
        Ok(()) | Err(TrySendError::Full(())) | Err(TrySendError::Disconnected(())) => {}
    }
}

/// What an event changes in the state.
fn apply(s: &mut Shared, event: &Event) {
    let drift = s.state.plan_kind == "drift";
    let st = &mut s.state;
    match event {
        Event::Connected { .. } => st.phase = "ramping".into(),
        Event::StepStarted {
            number,
            of,
            remaining,
            after,
            ..
        } => {
            st.step = *number;
            st.steps = *of;
            st.last_reading_v = None;
            st.running_mean_v = None;
            s.eta = Some((*remaining, *after, Instant::now()));
        }
        Event::Phase { phase, .. } => st.phase = phase_name(*phase, drift).into(),
        Event::Settle(p) => {
            st.table = Some(format!(
                "{} at {:+.4} °/s (demand {:+.4} °/s)",
                if p.ramping { "ramping" } else { "settling" },
                p.rate,
                p.demand
            ));
        }
        Event::Acquiring { latest, mean, .. } => {
            if latest.is_some() {
                st.last_reading_v = *latest;
            }
            st.running_mean_v = mean.is_finite().then_some(*mean);
        }
        Event::Stopping { from_dps, .. } => {
            st.phase = "ending".into();
            st.table = Some(match from_dps {
                Some(r) => format!("stopping from {r:+.4} °/s"),
                None => "stopping".into(),
            });
        }
        Event::Rest(rest) => {
            st.table = Some(match rest {
                TableRest::AtRest { rate_dps, .. } => format!("at rest ({rate_dps:+.4} °/s)"),
                TableRest::NotConfirmed { reason } => {
                    format!("rest could NOT be confirmed: {reason}")
                }
                TableRest::NeverReached { reason } => format!("never reached: {reason}"),
                other => format!("{other:?}"),
            });
        }
        Event::Drift { adev_curve_v, .. } => st.adev_v.clone_from(adev_curve_v),
        Event::Soak {
            target_c,
            setpoint_c,
            air_c,
            gyro_c,
            ..
        } => {
            st.phase = "soaking".into();
            st.chamber = Some(LiveChamber {
                temperature_c: Some(gyro_c.unwrap_or(*air_c)).filter(|t| t.is_finite()),
                setpoint_c: setpoint_c.is_finite().then_some(*setpoint_c),
                target_c: target_c.is_finite().then_some(*target_c),
            });
        }
        _ => {}
    }
}

impl Sink for LiveFile {
    fn connected(&mut self, _c: &Connected) -> Result<(), SinkError> {
        self.update(true, |s| s.state.phase = "ramping".into());
        Ok(())
    }

    fn recorded(&mut self, r: &Recorded<'_>, _: &mut Vec<Event>) -> Result<(), SinkError> {
        let row = r.row;
        self.update(true, |s| {
            s.state.steps_done += 1;
            s.state.step = row.step + 1;
            s.state.running_mean_v = Some(row.volts);
            s.state.step_summaries.push(StepSummary {
                number: row.step + 1,
                rate_dps: row.rate_dps,
                volts: row.volts,
                volts_std: row.volts_std,
                n: row.n,
                overloads: row.overloads,
                t_end_s: row.t_end_s,
            });
        });
        Ok(())
    }

    fn event(&mut self, event: &Event) -> Result<(), SinkError> {
        let force = matches!(event, Event::Stopping { .. } | Event::Rest(_));
        self.update(force, |s| apply(s, event));
        Ok(())
    }

    fn finish(&mut self, f: &Finish) -> Result<(), SinkError> {
        // the writer thread ends; the last state is written here (the run is over, a write
        // of a few kilobytes costs it nothing)
        self.end_writer();
        let snap = {
            let mut s = lock(&self.shared);
            let (status, phase) = match f.status {
                Status::Complete => ("complete", "done"),
                Status::Aborted => ("aborted", "aborted"),
                Status::Running => ("running", "ending"),
                Status::Failed => ("failed", "failed"),
            };
            s.state.status = status.into();
            s.state.phase = phase.into();
            s.state.reason = f.reason.clone();
            s.eta = None;
            s.state.eta_s = Some(0.0);
            let now = std::time::SystemTime::now();
            let end = if s.virtual_time {
                s.state
                    .started_utc
                    .as_deref()
                    .and_then(gyrocal_files::parse_rfc3339_utc)
                    .and_then(|t0| {
                        Duration::try_from_secs_f64(f.elapsed_s)
                            .ok()
                            .and_then(|d| t0.checked_add(d))
                    })
                    .unwrap_or(now)
            } else {
                now
            };
            s.state.ended_utc = Some(gyrocal_files::rfc3339_utc(end));
            s.snapshot()
        };
        deliver(
            &self.publisher,
            &self.path,
            &snap,
            "the run's own files are not affected",
        );
        Ok(())
    }

    fn live(&mut self) -> Option<LiveFn> {
        let shared = self.shared.clone();
        let wake = self.wake.clone();
        Some(Arc::new(move |e| {
            apply(&mut lock(&shared), &e);
            poke(&shared, wake.as_ref(), false);
        }))
    }
}

impl LiveFile {
    /// Ends the writer thread and waits for it (at most one write of a few kilobytes).
    fn end_writer(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(wake) = self.wake.take() {
            // a full buffer already wakes it; a closed one means it has ended
            let _ = wake.try_send(());
        }
        if let Some(w) = self.writer.take() {
            let _ = w.join();
        }
    }
}

impl Drop for LiveFile {
    fn drop(&mut self) {
        self.end_writer();
    }
}

/// Reads a `live.json` (a viewer's side): `None` when it is missing or not a live state.
pub fn read_live(dir: &Path) -> Option<LiveState> {
    let bytes = std::fs::read(dir.join(LIVE_JSON)).ok()?;
    serde_json::from_slice(&bytes).ok()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use gyrocal_files::plan::{Acquire, Step};
    use gyrocal_files::rundir::StepRecord;
    use gyrocal_files::steps::Record;

    fn header() -> LiveHeader {
        LiveHeader {
            run_id: "r1".into(),
            plan_name: "paper".into(),
            plan_kind: "scale_factor".into(),
            steps: 3,
            ..LiveHeader::default()
        }
    }

    fn wait_for(dir: &Path, f: impl Fn(&LiveState) -> bool) -> LiveState {
        for _ in 0..200 {
            if let Some(s) = read_live(dir)
                && f(&s)
            {
                return s;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        panic!(
            "live.json never reached the expected state: {:?}",
            read_live(dir)
        );
    }

    /// The engine's monitors keep the live closure (a sender of the writer's channel) until
    /// after the sinks are told the run finished: `finish` must end the writer anyway. It
    /// joined on the channel closing before, and every `gyrocal run` hung at its end.
    #[test]
    fn finish_returns_while_the_live_closure_is_still_held() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        let (done_tx, done_rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut live = LiveFile::new(&dir, header());
            let held = live.live();
            let _ = live.finish(&Finish {
                status: Status::Complete,
                reason: None,
                elapsed_s: 1.0,
                timing: None,
            });
            let _ = done_tx.send(());
            drop(held);
        });
        assert!(
            done_rx.recv_timeout(Duration::from_secs(10)).is_ok(),
            "finish did not return while the live closure was held"
        );
        let s = wait_for(tmp.path(), |s| s.status == "complete");
        assert_eq!(s.phase, "done");
    }

    #[test]
    fn live_json_follows_the_steps_and_says_how_the_run_ended() {
        let tmp = tempfile::tempdir().unwrap();
        let mut live = LiveFile::new(tmp.path(), header());
        let s = wait_for(tmp.path(), |s| s.phase == "connecting");
        assert_eq!(s.pid, std::process::id());
        assert!(!s.updated_utc.is_empty());
        for i in 0..2 {
            let step = Step {
                index: i,
                pass: 0,
                rate_dps: 10.0 * i as f64,
                acquire: Acquire::Samples(10),
                series: None,
            };
            live.event(&Event::Phase {
                step: i,
                phase: Phase::Acquiring,
            })
            .unwrap();
            let row = StepRecord {
                step: i,
                pass: 0,
                rate_dps: step.rate_dps,
                rate_meas_dps: None,
                rate_meas_std_dps: None,
                rate_meas_min_dps: None,
                rate_meas_max_dps: None,
                rate_samples: None,
                volts: 0.5 * i as f64,
                volts_std: Some(1e-4),
                n: 10,
                overloads: 0,
                retries: 0,
                t_start_s: 0.0,
                series: None,
                t_end_s: 1.0,
            };
            let rec = Record::Row(step);
            live.recorded(
                &Recorded {
                    step: &step,
                    record: &rec,
                    row: &row,
                    volts: &[],
                    t_start: 0.0,
                    t_end: 1.0,
                    elapsed_s: 1.0,
                },
                &mut Vec::new(),
            )
            .unwrap();
        }
        // a step's end is written at once, whatever the interval
        let s = wait_for(tmp.path(), |s| s.steps_done == 2);
        assert_eq!(s.step_summaries.len(), 2);
        assert_eq!(s.step_summaries[1].rate_dps, 10.0);
        live.finish(&Finish {
            status: Status::Complete,
            reason: None,
            elapsed_s: 2.0,
            timing: None,
        })
        .unwrap();
        let s = read_live(tmp.path()).unwrap();
        assert_eq!((s.phase.as_str(), s.status.as_str()), ("done", "complete"));
        // no temporary file left behind
        let names: Vec<_> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from(LIVE_JSON)]);
    }

    #[test]
    fn the_end_is_the_wall_clock_or_in_virtual_time_the_start_plus_the_run_clock() {
        use std::time::SystemTime;
        let end_of = |virtual_time: bool| {
            let tmp = tempfile::tempdir().unwrap();
            let mut live = LiveFile::new(
                tmp.path(),
                LiveHeader {
                    started_utc: Some("2026-12-07T08:00:00.000Z".into()),
                    virtual_time,
                    ..header()
                },
            );
            let running = live.handle().state();
            assert_eq!(running.ended_utc, None, "an end while running");
            live.finish(&Finish {
                status: Status::Complete,
                reason: None,
                elapsed_s: 3600.5,
                timing: None,
            })
            .unwrap();
            let s = read_live(tmp.path()).unwrap();
            assert_eq!(s.started_utc.as_deref(), Some("2026-12-07T08:00:00.000Z"));
            s.ended_utc.unwrap()
        };
        assert_eq!(end_of(true), "2026-12-07T09:00:00.500Z");
        let before = SystemTime::now() - Duration::from_secs(1);
        let wall = gyrocal_files::parse_rfc3339_utc(&end_of(false)).unwrap();
        assert!(wall >= before && wall <= SystemTime::now(), "not the wall clock");
    }

    #[test]
    fn a_directory_that_cannot_be_written_is_not_a_run_failure() {
        let tmp = tempfile::tempdir().unwrap();
        let gone = tmp.path().join("missing");
        let mut live = LiveFile::new(&gone, header());
        assert!(
            live.event(&Event::Rest(TableRest::NotConfirmed { reason: "x".into() }))
                .is_ok()
        );
        assert!(
            live.finish(&Finish {
                status: Status::Failed,
                reason: Some("boom".into()),
                elapsed_s: 0.0,
                timing: None,
            })
            .is_ok()
        );
        assert!(!gone.exists());
    }

    /// A series' soak shows as `soaking` with the gyro's temperature and the setpoint; the
    /// analysis's verdict reaches the last state written and the publisher (the catalog's
    /// bus), after the sinks were told the run finished.
    #[test]
    fn a_drift_segment_brings_the_running_allan_curve_and_an_older_reader_skips_it() {
        let tmp = tempfile::tempdir().unwrap();
        let mut live = LiveFile::new(tmp.path(), header());
        let handle = live.handle();
        assert!(handle.state().adev_v.is_empty());
        let curve = vec![(0.0217, 3e-5), (0.0434, 2.1e-5), (0.0868, 1.5e-5)];
        live.event(&Event::Drift {
            segment: 2,
            of: 10,
            readings: 6000,
            elapsed_s: 130.0,
            adev_v: vec![(0.0217, 3e-5)],
            adev_curve_v: curve.clone(),
        })
        .unwrap();
        assert_eq!(handle.state().adev_v, curve);
        // written as a member of its own, absent when empty (a sweep's file is unchanged)
        let json = serde_json::to_value(handle.state()).unwrap();
        assert_eq!(json["adev_v"][2][1], 1.5e-5);
        let mut sweep = handle.state();
        sweep.adev_v.clear();
        let json = serde_json::to_string(&sweep).unwrap();
        assert!(!json.contains("adev_v"), "{json}");
        let back: LiveState = serde_json::from_str(&json).unwrap();
        assert!(back.adev_v.is_empty());
    }

    #[test]
    fn a_soak_shows_its_temperatures_and_the_last_write_carries_the_verdict() {
        let tmp = tempfile::tempdir().unwrap();
        let seen: Arc<Mutex<Vec<LiveState>>> = Arc::new(Mutex::new(Vec::new()));
        let publisher: Publisher = {
            let seen = seen.clone();
            Arc::new(move |s: &LiveState| seen.lock().unwrap().push(s.clone()))
        };
        let mut live = LiveFile::new(tmp.path(), header()).with_publisher(publisher);
        let handle = live.handle();
        live.event(&Event::Soak {
            point: 1,
            target_c: 60.0,
            setpoint_c: 42.5,
            air_c: 41.0,
            gyro_c: Some(38.25),
            held: None,
            soak: Duration::from_secs(600),
            waited: Duration::from_secs(30),
        })
        .unwrap();
        let now = handle.state();
        assert_eq!(now.phase, "soaking");
        let c = now.chamber.unwrap();
        assert_eq!(c.temperature_c, Some(38.25));
        assert_eq!(c.setpoint_c, Some(42.5));
        assert_eq!(c.target_c, Some(60.0));
        // without a product sensor the air is what the gyro sees
        live.event(&Event::Soak {
            point: 1,
            target_c: 60.0,
            setpoint_c: 60.0,
            air_c: 59.5,
            gyro_c: None,
            held: None,
            soak: Duration::from_secs(600),
            waited: Duration::from_secs(40),
        })
        .unwrap();
        assert_eq!(handle.state().chamber.unwrap().temperature_c, Some(59.5));
        live.finish(&Finish {
            status: Status::Complete,
            reason: None,
            elapsed_s: 2.0,
            timing: None,
        })
        .unwrap();
        assert_eq!(read_live(tmp.path()).unwrap().verdict, None);
        handle.conclude(Some("marginal"));
        let last = read_live(tmp.path()).unwrap();
        assert_eq!(
            (last.status.as_str(), last.verdict.as_deref()),
            ("complete", Some("marginal"))
        );
        assert_eq!(last.chamber.unwrap().setpoint_c, Some(60.0));
        let published = seen.lock().unwrap();
        assert_eq!(
            published.last().and_then(|s| s.verdict.as_deref()),
            Some("marginal"),
            "the publisher was not handed the concluded state"
        );
        assert!(published.iter().any(|s| s.status == "complete"));
    }

    /// A live.json of the first format without the soak's members still reads.
    #[test]
    fn a_state_without_the_soak_members_reads() {
        let tmp = tempfile::tempdir().unwrap();
        let live = LiveFile::new(tmp.path(), header());
        let mut v = serde_json::to_value(live.handle().state()).unwrap();
        let o = v.as_object_mut().unwrap();
        o.remove("chamber");
        let back: LiveState = serde_json::from_value(v).unwrap();
        assert_eq!(back.chamber, None);
        assert_eq!(back.run_id, "r1");
    }
}
