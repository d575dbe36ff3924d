//! The calibration sequencer: for each step of the plan, demand the rate, wait until the table
//! is at rate, dwell, acquire, record; at the end stop the table and fit.
//!
//! Why it looks the way it does:
//!
//! - **Nothing is recorded that is not complete.** A step's row goes to `steps.csv` (fsynced,
//!   after its samples) only when all its readings are in; a resume drops whatever a step left
//!   behind and runs it again.
//! - **The table is stopped on every way out.** Errors, a stop request (Ctrl-C, SIGTERM) and a
//!   dropped future all end in the same cleanup: a controlled stop through the table's
//!   [`StopHandle`] (an emergency stop on a second request), a device clear and `SYST:LOC` for
//!   the multimeter, and the manifest marked `aborted` or `failed` with the reason.
//! - **No instrument time is wasted.** The table is on another port than the multimeter, so in
//!   memory mode the last burst of a step is fetched while the table already ramps to the next
//!   rate; the stability window counts towards the settling dwell (the table is at rate during
//!   it); streaming overlaps the transfer with the measurement. The run reports its elapsed time
//!   against the physical bound of [`crate::estimate`].
//! - **Time is the run's own clock** (tokio's `Instant`), so a simulated run in virtual time is
//!   exact and reproducible, and the same code runs in real time on real instruments.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use gyrocal_meter::{Acquired, ErrorKind, Measured, MeterError, Multimeter, Reading};
use gyrocal_table::{RateStats, RateTable, SettleCriteria, StopHandle, TableError, TableMode};
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tracing::Instrument as _;

use crate::estimate::{self, Estimate};
use crate::monitor::{self, AdevWatch, WarmupWatch};
use crate::plan::{Plan, PlanKind, Step, TableRole};
use crate::rundir::{
    Instruments, Retry, RunDir, RunError, Sample, Status, StepRecord, Timing as RunTiming,
    WarmupRecord,
};

/// What the operator (or a signal) asked for. The `&'static str` names who asked (`"SIGINT"`,
/// `"SIGHUP"`, `"operator"`, ...): the manifest's reason and the exit code say it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StopRequest {
    /// Keep going.
    #[default]
    None,
    /// Stop: controlled stop of the table, wait for rest, run marked `aborted`.
    Controlled(&'static str),
    /// Stop now: emergency stop of the table (interlock open), run marked `aborted`.
    Emergency(&'static str),
}

impl StopRequest {
    /// Who asked for the stop (`None` for [`StopRequest::None`]).
    pub fn cause(&self) -> Option<&'static str> {
        match self {
            StopRequest::None => None,
            StopRequest::Controlled(c) | StopRequest::Emergency(c) => Some(c),
        }
    }
}

/// Where the table was left at the end of a run, as far as gyrocal could tell. An operator is
/// never told "stopped" unless the table itself said so.
#[derive(Debug, Clone, PartialEq)]
pub enum TableRest {
    /// The table reported rest: |measured rate| within the stop tolerance and mode OFF.
    AtRest {
        /// The last measured rate, °/s.
        rate_dps: f64,
        /// How long the wait for rest took after the stop was sent.
        waited: Duration,
    },
    /// Rest could not be confirmed: the table stopped answering, its port is gone, or it was
    /// still turning at the deadline. Someone must stop it by hand.
    NotConfirmed {
        /// Why.
        reason: String,
    },
    /// The table never answered in this session, so gyrocal never moved it; its state is
    /// unknown (an earlier session may have left it turning).
    NeverReached {
        /// Why.
        reason: String,
    },
    /// The plan has no table (`[drift] table = "none"`): nothing was opened or moved.
    NoTable,
}

impl TableRest {
    /// True only when the table confirmed rest.
    pub fn is_at_rest(&self) -> bool {
        matches!(self, TableRest::AtRest { .. })
    }

    /// True when nothing can be left turning: the table confirmed rest, or the plan has none.
    /// (The operator's "stop it by hand" applies to neither.)
    pub fn nothing_turning(&self) -> bool {
        matches!(self, TableRest::AtRest { .. } | TableRest::NoTable)
    }
}

/// The phase of a step, for progress displays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// The table ramps to the step's rate (and waits for the stability window).
    Ramping,
    /// Dwelling at rate before acquiring.
    Settling,
    /// The multimeter is reading.
    Acquiring,
    /// Readings are transferred from the multimeter's memory.
    Fetching,
}

/// Progress events, sent on an unbounded channel so a display never slows the run down.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// Both instruments answered.
    Connected {
        /// The multimeter's `*IDN?`.
        dmm: String,
        /// The table's `*IDN?`.
        table: String,
    },
    /// The schedule this session runs, with its estimate.
    Planned {
        /// Steps to run in this session.
        steps: usize,
        /// Steps already done (resume).
        done: usize,
        /// Expected duration of the remaining steps.
        estimate: Duration,
        /// How the multimeter acquires (`stream`, `memory`, ...).
        acquisition: &'static str,
    },
    /// A step begins. Operators see one numbering, the plan's: `number` of `of` (`step 4/19`),
    /// the same in every session of a resumed run; the run directory's `step` column is the
    /// 0-based index (`number - 1`).
    StepStarted {
        /// The step.
        step: Step,
        /// 1-based number of the step in the plan's schedule (`step.index + 1`).
        number: usize,
        /// Steps in the plan's schedule.
        of: usize,
        /// 1-based position in this session's steps (a step measured again counts twice).
        position: usize,
        /// Steps in this session.
        total: usize,
        /// Estimated time to the end of the run from the start of this step (the instruments'
        /// timing models, see [`crate::estimate`]).
        remaining: Duration,
        /// Of `remaining`, what the steps after this one take: a display counts the time down
        /// within the step from `remaining` towards it.
        after: Duration,
    },
    /// A sample of the table while waiting for the rate.
    Settle(gyrocal_table::SettleProgress),
    /// A step entered a phase.
    Phase {
        /// Step index.
        step: usize,
        /// The phase.
        phase: Phase,
    },
    /// A reading received in the current acquisition.
    Acquiring {
        /// Readings so far.
        done: usize,
        /// Readings asked for.
        total: usize,
        /// The reading just received, V (`None`: an overload).
        latest: Option<f64>,
        /// Mean of this acquisition's valid readings so far, V (NaN before the first).
        mean: f64,
        /// Their sample standard deviation, V (`None` below two readings).
        std: Option<f64>,
    },
    /// A step was recorded.
    StepDone(StepRecord),
    /// The warm-up's state after a chunk of readings (also written to the manifest).
    Warmup(WarmupRecord),
    /// A segment of a drift record was recorded: the record so far and its running overlapping
    /// Allan deviation at octave τ near 1, 10 and 100 s (in volts; this session's readings).
    Drift {
        /// 1-based number of the segment just recorded.
        segment: usize,
        /// Segments in the plan.
        of: usize,
        /// Readings in this session's record so far.
        readings: u64,
        /// The run clock at the end of the segment, s (earlier sessions included).
        elapsed_s: f64,
        /// `(τ, σ)`, s and V.
        adev_v: Vec<(f64, f64)>,
    },
    /// A recovery was needed (logged in the manifest too).
    Retry(Retry),
    /// The run is ending: the table was sent a stop and gyrocal waits until it is at rest.
    Stopping {
        /// The table's measured rate when the stop was sent, °/s (`None` if it did not answer).
        from_dps: Option<f64>,
        /// The emergency stop (interlock open) was sent.
        emergency: bool,
        /// How long gyrocal waits for rest before telling the operator it could not confirm it.
        deadline: Duration,
    },
    /// The end state of the table (the last event of a run).
    Rest(TableRest),
}

/// Tunables of the sequencer that are not in the plan.
#[derive(Debug, Clone, PartialEq)]
pub struct SequencerOptions {
    /// Table sampling interval while waiting, dwelling and acquiring (each sample is also a
    /// heartbeat). Default 200 ms.
    pub sample_interval: Duration,
    /// Time allowed for each cleanup exchange with an instrument after an error. Default 5 s.
    pub cleanup_timeout: Duration,
    /// Fetch a memory burst while the table ramps to the next rate. Default true.
    pub overlap_fetch: bool,
    /// A step is refused when any table sample during its acquisition is further from the
    /// demand than this many times the plan's `rate_tolerance_dps` (or the mean of its
    /// samples is further than the tolerance itself). Default 5: readback noise and the
    /// once-per-turn ripple make single samples cross the at-rate tolerance now and then,
    /// while a fault, an opened interlock or a lost servo moves the rate by far more.
    pub hold_tolerance_factor: f64,
    /// Times a step the table did not hold is measured again (the table is healthy again:
    /// it reached the rate and held it for the stability window) before the run fails.
    /// Default 1.
    pub step_retries: u32,
    /// Times a step whose readings the meter lost before they were fetched (its memory was
    /// cleared: a power cycle, or the meter's own recovery configured it again) is measured
    /// again before the run fails. Default 2. This bounds the loop as a whole: a meter that
    /// loses a step's readings at every attempt (one whose replies are too late for its
    /// recovery, say) ends the run after 1 + this many attempts at that step, with the
    /// meter's own words for what cleared its memory.
    pub lost_retries: u32,
}

impl Default for SequencerOptions {
    fn default() -> Self {
        SequencerOptions {
            sample_interval: Duration::from_millis(200),
            cleanup_timeout: Duration::from_secs(5),
            overlap_fetch: true,
            hold_tolerance_factor: 5.0,
            step_retries: 1,
            lost_retries: 2,
        }
    }
}

/// Why a run did not complete.
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    /// The multimeter failed (after its own retries).
    #[error("multimeter: {0}")]
    Dmm(Box<dyn MeterError>),
    /// The rate table failed or faulted.
    #[error("rate table: {0}")]
    Table(Box<TableError>),
    /// The run directory could not be written.
    #[error("run directory: {0}")]
    RunDir(Box<RunError>),
    /// A step produced no valid reading.
    #[error(
        "step {} at {rate_dps} °/s: all {count} readings were overloads (9.9E+37); is range_v too small?",
        .step + 1
    )]
    AllOverloaded {
        /// Step index (0-based; messages say `index + 1`, the plan's step number).
        step: usize,
        /// The step's rate.
        rate_dps: f64,
        /// Readings taken.
        count: usize,
    },
    /// The table did not hold the step's rate for its whole acquisition: the step is not
    /// recorded.
    #[error("step {} at {rate_dps} °/s not recorded: {detail}", .step + 1)]
    NotHeld {
        /// Step index (0-based; messages say `index + 1`, the plan's step number).
        step: usize,
        /// The step's rate.
        rate_dps: f64,
        /// What the table did.
        detail: String,
    },
    /// The instruments now answering are simulators and the recorded steps were measured, or
    /// the reverse: continuing would mix simulated and measured data in one calibration.
    #[error(
        "the recorded steps of this run were measured on {recorded_on}, and the instruments now \
         answering are {now}: continuing would mix simulated and measured data in one \
         calibration; start a new run"
    )]
    Mixed {
        /// What the recorded steps were measured on.
        recorded_on: &'static str,
        /// What answers now.
        now: &'static str,
    },
    /// The run was stopped by the operator or a signal.
    #[error("{}", stopped_text(.0))]
    Stopped(StopRequest),
    /// The meter lost a step's readings at every attempt allowed
    /// ([`SequencerOptions::lost_retries`]): the run ends rather than measure it for ever.
    #[error(
        "step {} at {rate_dps} °/s not recorded: the multimeter lost its readings at all \
         {attempts} attempts, the most allowed; the last time: {last}",
        .step + 1
    )]
    ReadingsLostAgain {
        /// Step index (0-based; messages say `index + 1`, the plan's step number).
        step: usize,
        /// The step's rate.
        rate_dps: f64,
        /// Attempts at the step, the first included.
        attempts: u32,
        /// The meter's last error (it says what cleared its memory).
        last: Box<dyn MeterError>,
    },
    /// The sequencer panicked (a bug); the table was still brought to rest.
    #[error("internal error (panic) in the sequencer: {0}")]
    Panicked(String),
}

fn stopped_text(req: &StopRequest) -> String {
    match req {
        StopRequest::Emergency(by) => format!("stopped by {by} (emergency stop)"),
        StopRequest::Controlled(by) => format!("stopped by {by} (controlled stop)"),
        StopRequest::None => "stopped".into(),
    }
}

// The drivers' errors carry context (device, command, bytes) and are large; boxed, the
// sequencer's results stay small on every `?` path. A meter's error keeps its kind.
fn dmm_error<E: MeterError>(e: E) -> SequenceError {
    SequenceError::Dmm(Box::new(e))
}

impl From<TableError> for SequenceError {
    fn from(e: TableError) -> Self {
        SequenceError::Table(Box::new(e))
    }
}

impl From<RunError> for SequenceError {
    fn from(e: RunError) -> Self {
        SequenceError::RunDir(Box::new(e))
    }
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSummary {
    /// `complete`, `aborted` or `failed`.
    pub status: Status,
    /// Why, when not complete.
    pub reason: Option<String>,
    /// Steps recorded in this session.
    pub steps_recorded: usize,
    /// The session's bound versus elapsed, when it completed.
    pub timing: Option<RunTiming>,
    /// Elapsed on the run clock, including earlier sessions, s.
    pub elapsed_s: f64,
    /// Where the table was left, as far as gyrocal could confirm.
    pub table: TableRest,
    /// Whether resuming the same plan can complete the run. False when the plan itself must
    /// change (every reading of a step overloaded: the range is too small), which makes it
    /// another plan: a new run.
    pub resumable: bool,
    /// An emergency stop was sent (by a second signal, after a table fault, or because the
    /// controlled stop could not be sent): the table's interlock is open and must be re-armed
    /// at the table before the run is resumed.
    pub emergency_stop: bool,
}

/// What the steps share: how to reach the rate and how to read.
struct StepContext {
    criteria: SettleCriteria,
    accel: f64,
    dwell: Duration,
    reading_time: Duration,
}

/// How a step ended (errors aside).
enum StepOutcome<P> {
    /// Its readings and row are on disk.
    Recorded,
    /// Its readings are in the meter's memory, to be fetched during the next ramp.
    Pending(P),
    /// Nothing was recorded and the step must be measured again: the table did not hold the
    /// rate during the acquisition, or the meter lost the readings (a power cycle).
    Again {
        /// `table` or `dmm`: whose doing.
        instrument: &'static str,
        /// What happened.
        detail: String,
    },
}

/// A step whose last readings are still in the meter.
struct PendingFetch<P> {
    step: Step,
    pending: P,
    stats: RateStats,
    t_start: f64,
    t_end: f64,
}

/// The sequencer. Build it with the multimeter and the rate table (any [`Multimeter`], any
/// [`RateTable`]: the CLI chooses them from the plan), the run directory and the plan, then
/// call [`Sequencer::run`].
pub struct Sequencer<M: Multimeter, T: RateTable> {
    plan: Plan,
    dmm: Option<M>,
    table: T,
    stop_handle: StopHandle,
    run: RunDir,
    options: SequencerOptions,
    events: Option<mpsc::UnboundedSender<Event>>,
    origin: Instant,
    offset_s: f64,
    recorded: usize,
    /// The table identified itself in this session.
    table_reached: bool,
    /// A rate was demanded in this session.
    moved: bool,
    /// An emergency stop was sent in this session (the interlock is open).
    emergency_sent: bool,
    /// Steps whose readings the meter lost before they were fetched, to measure again.
    lost: Vec<Step>,
    /// How many times each step's readings were lost (bounded by
    /// [`SequencerOptions::lost_retries`]).
    lost_count: HashMap<usize, u32>,
    /// The warm-up being watched (a drift record's first segments; see [`crate::monitor`]).
    warmup: Option<WarmupWatch>,
    /// A drift record's running Allan deviation.
    adev: Option<AdevWatch>,
}

impl<M: Multimeter, T: RateTable> Sequencer<M, T> {
    /// A sequencer for `plan` writing to `run` (fresh or opened for resume).
    pub fn new(plan: Plan, dmm: M, table: T, run: RunDir, options: SequencerOptions) -> Self {
        let stop_handle = table.stop_handle();
        let offset_s = run.manifest().elapsed_s;
        Sequencer {
            plan,
            dmm: Some(dmm),
            table,
            stop_handle,
            run,
            options,
            events: None,
            origin: Instant::now(),
            offset_s,
            recorded: 0,
            table_reached: false,
            moved: false,
            emergency_sent: false,
            lost: Vec::new(),
            lost_count: HashMap::new(),
            warmup: None,
            adev: None,
        }
    }

    /// Sends progress events to `tx`.
    pub fn with_events(mut self, tx: mpsc::UnboundedSender<Event>) -> Self {
        self.events = Some(tx);
        self
    }

    /// The table's stop handle, for a signal handler's emergency stop.
    pub fn stop_handle(&self) -> StopHandle {
        self.stop_handle.clone()
    }

    /// The run directory (for the caller to fit, report and inspect after the run).
    pub fn run_dir(&self) -> &RunDir {
        &self.run
    }

    /// Consumes the sequencer and returns the run directory.
    pub fn into_run_dir(self) -> RunDir {
        self.run
    }

    fn now_s(&self) -> f64 {
        self.offset_s + self.origin.elapsed().as_secs_f64()
    }

    fn emit(&self, event: Event) {
        if let Some(tx) = &self.events {
            let _ = tx.send(event);
        }
    }

    /// Runs the remaining steps of the plan until done, failed or stopped through `stop`.
    /// Whatever happens (a panic inside the steps included), the table is stopped and waited
    /// for until it reports rest (a further [`StopRequest::Emergency`] during that wait sends
    /// the emergency stop at once), the multimeter returned to local and the manifest left
    /// with a final status; the summary says which, and where the table was left. The fit is
    /// the caller's (see `gyrocal_analysis::sweep::fit_run`), so a failed fit never loses the data.
    pub async fn run(&mut self, mut stop: watch::Receiver<StopRequest>) -> RunSummary {
        use futures_util::FutureExt as _;
        self.origin = Instant::now();
        // the run directory converts run-clock times into UTC from this instant
        self.run.anchor_clock(self.offset_s);
        let run_span =
            tracing::info_span!("run", plan = %self.plan.name(), dir = %self.run.path().display());
        let outcome = {
            let wait_stop = async {
                loop {
                    let req = *stop.borrow_and_update();
                    if req != StopRequest::None {
                        return req;
                    }
                    if stop.changed().await.is_err() {
                        // sender gone: nobody can ask for a stop any more
                        std::future::pending::<()>().await;
                    }
                }
            };
            // A panic in the steps (a bug) must not skip the stop below: it becomes an error
            // here, with the table driver still in hand to confirm rest.
            let steps =
                std::panic::AssertUnwindSafe(self.steps().instrument(run_span)).catch_unwind();
            tokio::select! {
                biased;
                req = wait_stop => Err(SequenceError::Stopped(req)),
                r = steps => r.unwrap_or_else(|panic| Err(SequenceError::Panicked(panic_text(&panic)))),
            }
        };
        match outcome {
            Ok(timing) => self.finish_ok(timing, &mut stop).await,
            Err(e) => {
                let emergency = matches!(e, SequenceError::Stopped(StopRequest::Emergency(_)))
                    || matches!(*stop.borrow(), StopRequest::Emergency(_));
                self.finish_err(e, emergency, &mut stop).await
            }
        }
    }

    async fn finish_ok(
        &mut self,
        timing: RunTiming,
        stop: &mut watch::Receiver<StopRequest>,
    ) -> RunSummary {
        // `steps` sent the controlled stop; the run ends when the table says it is at rest
        let table = self.bring_to_rest(stop, false).await;
        self.release_dmm(false).await;
        let elapsed_s = self.now_s();
        // The data are complete whatever the table does now; a table that did not confirm
        // rest is said in the manifest and by the caller, but does not void the calibration.
        let note = match &table {
            TableRest::AtRest { .. } | TableRest::NoTable => None,
            TableRest::NotConfirmed { reason } | TableRest::NeverReached { reason } => {
                Some(format!(
                    "all steps recorded, but the table could NOT be confirmed at rest: {reason}"
                ))
            }
        };
        let mut summary = RunSummary {
            status: Status::Complete,
            reason: note.clone(),
            steps_recorded: self.recorded,
            timing: Some(timing.clone()),
            elapsed_s,
            table,
            resumable: false,
            emergency_stop: self.emergency_sent,
        };
        let result = self
            .run
            .set_timing(timing)
            .and_then(|()| self.log_table_retries(None))
            .and_then(|()| self.run.finish(Status::Complete, note, elapsed_s));
        if let Err(e) = result {
            tracing::error!(error = %e, "could not close the run directory");
            summary.status = Status::Failed;
            summary.reason = Some(format!("run directory: {e}"));
        }
        summary
    }

    async fn finish_err(
        &mut self,
        error: SequenceError,
        emergency: bool,
        stop: &mut watch::Receiver<StopRequest>,
    ) -> RunSummary {
        let status = match error {
            SequenceError::Stopped(_) => Status::Aborted,
            _ => Status::Failed,
        };
        let reason = error.to_string();
        let resumable = !matches!(
            error,
            SequenceError::AllOverloaded { .. } | SequenceError::Mixed { .. }
        );
        tracing::warn!(%reason, ?status, "run stopping");
        // Table first: it is the dangerous one. A table that faulted or stopped answering gets
        // the emergency path too (rate-table.md: "for a second interrupt or a fault"): a
        // controlled stop that was written may still not have been heard.
        let table_fault = matches!(&error, SequenceError::Table(e) if e.ends_run());
        let stopped = if emergency {
            self.stop_handle.emergency_stop().await
        } else {
            self.stop_handle.stop().await
        };
        if let Err(e) = &stopped {
            tracing::error!(error = %e, "stop command failed; trying the emergency stop");
        }
        let mut emergency_sent = emergency;
        if !emergency && (table_fault || stopped.is_err()) {
            tracing::warn!("table fault: emergency stop (interlock open)");
            emergency_sent = true;
            if let Err(e) = self.stop_handle.emergency_stop().await {
                tracing::error!(error = %e, "emergency stop failed: STOP THE TABLE BY HAND");
            }
        }
        self.emergency_sent |= emergency_sent;
        let table = self.bring_to_rest(stop, emergency_sent).await;
        self.release_dmm(true).await;
        let elapsed_s = self.now_s();
        // the record says an emergency stop when one was sent, whatever the first request was
        let reason = if self.emergency_sent && !reason.contains("emergency stop") {
            format!("{reason}; then an emergency stop (interlock open)")
        } else {
            reason
        };
        if let Err(e) = self
            .log_table_retries(None)
            .and_then(|()| self.run.finish(status, Some(reason.clone()), elapsed_s))
        {
            tracing::error!(error = %e, "could not write the final manifest");
        }
        RunSummary {
            status,
            reason: Some(reason),
            steps_recorded: self.recorded,
            timing: None,
            elapsed_s,
            table,
            resumable,
            emergency_stop: self.emergency_sent,
        }
    }

    /// After a stop was sent: waits until the table reports rest (|rate| within its stop
    /// tolerance, mode OFF), at most the time a stop from the measured rate at the plan's
    /// acceleration can take plus a margin. An emergency request arriving meanwhile sends the
    /// emergency stop at once (from a task of its own: the wait may hold the table's link).
    /// Says honestly what it found; never fails.
    async fn bring_to_rest(
        &mut self,
        stop: &mut watch::Receiver<StopRequest>,
        emergency_sent: bool,
    ) -> TableRest {
        if !self.plan.has_table() {
            tracing::info!("no rate table in this plan: nothing to bring to rest");
            self.emit(Event::Rest(TableRest::NoTable));
            return TableRest::NoTable;
        }
        let limit = self.options.cleanup_timeout;
        let from = match tokio::time::timeout(limit, self.table.read_rate()).await {
            Ok(Ok(r)) => Some(r),
            Ok(Err(e)) => {
                tracing::warn!(error = %e, "could not read the table's rate after the stop");
                None
            }
            Err(_) => None,
        };
        let worst = from.map_or(self.plan.table().max_rate_dps, f64::abs);
        let deadline = self.table.stop_deadline(worst);
        self.emit(Event::Stopping {
            from_dps: from,
            emergency: emergency_sent,
            deadline,
        });
        tracing::info!(from_dps = ?from, ?deadline, "waiting for the table to come to rest");
        let started = Instant::now();
        let Self {
            table,
            stop_handle,
            emergency_sent: emergency_during,
            ..
        } = self;
        let mut watching = !emergency_sent;
        let result = {
            let mut wait = std::pin::pin!(table.wait_stopped(deadline));
            loop {
                tokio::select! {
                    r = &mut wait => break r,
                    changed = stop.changed(), if watching => {
                        if changed.is_err() {
                            watching = false;
                        } else if matches!(*stop.borrow_and_update(), StopRequest::Emergency(_)) {
                            watching = false;
                            *emergency_during = true;
                            tracing::warn!("emergency stop requested while the table decelerates");
                            let handle = stop_handle.clone();
                            tokio::spawn(async move {
                                if let Err(e) = handle.emergency_stop().await {
                                    tracing::error!(error = %e, "emergency stop failed: STOP THE TABLE BY HAND");
                                }
                            });
                        }
                    }
                }
            }
        };
        let rest = match result {
            Ok(report) => TableRest::AtRest {
                rate_dps: report.rate_dps,
                waited: started.elapsed(),
            },
            Err(e) if !self.table_reached && !self.moved => TableRest::NeverReached {
                reason: format!("the table did not answer ({e}); this session did not move it"),
            },
            Err(e) => TableRest::NotConfirmed {
                reason: e.to_string(),
            },
        };
        match &rest {
            TableRest::AtRest { .. } => tracing::info!("table at rest"),
            TableRest::NoTable => tracing::info!("no rate table: nothing turning"),
            TableRest::NotConfirmed { reason } | TableRest::NeverReached { reason } => {
                tracing::error!(%reason, "the table could NOT be confirmed at rest: stop it by hand")
            }
        }
        self.emit(Event::Rest(rest.clone()));
        rest
    }

    /// Recovery (after an interrupted exchange), then back to the front panel; bounded in
    /// time, errors logged (the run's outcome is already decided).
    async fn release_dmm(&mut self, after_error: bool) {
        let Some(mut dmm) = self.dmm.take() else {
            return;
        };
        let limit = self.options.cleanup_timeout;
        if after_error {
            match tokio::time::timeout(limit, dmm.recover()).await {
                Ok(Ok(note)) => tracing::info!(%note, "multimeter recovered at the stop"),
                Ok(Err(e)) => tracing::warn!(error = %e, "multimeter clear failed"),
                Err(_) => tracing::warn!("multimeter clear timed out"),
            }
        }
        match tokio::time::timeout(limit, dmm.release()).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::warn!(error = %e, "multimeter did not go back to local"),
            Err(_) => tracing::warn!("multimeter did not go back to local in time"),
        }
    }

    fn log_retry(
        &mut self,
        step: Option<usize>,
        instrument: &str,
        message: String,
    ) -> Result<(), RunError> {
        let retry = Retry {
            t_s: self.now_s(),
            step,
            instrument: instrument.into(),
            message,
        };
        tracing::warn!(step, instrument, message = %retry.message, "retry");
        self.emit(Event::Retry(retry.clone()));
        self.run.log_retry(retry)
    }

    /// Connects, configures and runs every remaining step; stops the table at the end.
    async fn steps(&mut self) -> Result<RunTiming, SequenceError> {
        let Some(dmm) = self.dmm.as_mut() else {
            return Err(released());
        };
        let dmm_identity = dmm.connect().await.map_err(dmm_error)?;
        let dmm_id = dmm_identity.raw.clone();
        let t = self.table.connect().await?;
        self.table_reached = true;
        let table_id = format!("{},{},{},{}", t.manufacturer, t.model, t.serial, t.version);
        // simulators say so in their serial field: a run's data are all simulated or all
        // measured, never both
        let prefix = crate::rundir::SIMULATOR_SERIAL_PREFIX;
        let simulators = dmm_identity.serial.starts_with(prefix) || t.serial.starts_with(prefix);
        let recorded = !self.run.done_steps().is_empty();
        if simulators != self.run.manifest().simulated {
            if recorded {
                return Err(SequenceError::Mixed {
                    recorded_on: if self.run.manifest().simulated {
                        "a simulated bench"
                    } else {
                        "real instruments"
                    },
                    now: if simulators {
                        "simulators"
                    } else {
                        "real instruments"
                    },
                });
            }
            if simulators {
                self.run
                    .mark_simulated("the instruments identify as simulators (serial SIM...)")?;
            }
        }
        self.emit(Event::Connected {
            dmm: dmm_id.clone(),
            table: table_id.clone(),
        });
        self.run.set_instruments(Instruments {
            dmm: Some(dmm_id),
            table: Some(table_id),
        })?;

        let dcv = estimate::dc_volts(&self.plan);
        let dmm = self.dmm_mut()?;
        dmm.configure(&dcv).await.map_err(dmm_error)?;
        let Some(timing) = dmm.timing() else {
            return Err(dmm_error(NoTiming));
        };
        let reading_time = timing.reading_time();
        let acquisition = timing.acquisition();
        if !self.plan.has_table() {
            tracing::info!("no rate table in this plan: the record is taken without one");
        } else if self.servo_off() {
            // a drift record with the servo off: the table is brought to rest (mode OFF, a
            // zero-rate hold with the servo still on), then the servo is switched off the
            // orderly way the controller offers (ACL `:Interlock:Open`: an ABORT profile to
            // zero, at rest already, then servo off), and it is never enabled again; the
            // driver knows the interlock event is its own
            self.table.stop().await?;
            let deadline = self.table.stop_deadline(self.plan.table().max_rate_dps);
            self.table.wait_stopped(deadline).await?;
            self.table.emergency_stop().await?;
            let rest = self.table.wait_stopped(deadline).await?;
            tracing::info!(
                rate_dps = rest.rate_dps,
                "table at rest, servo off, for the drift record"
            );
        } else {
            self.table.enable().await?;
        }

        let steps = self.run.remaining_steps();
        let est: Estimate = estimate::estimate(&self.plan, &steps, 0.0, timing.as_ref());
        self.emit(Event::Planned {
            steps: steps.len(),
            done: self.run.done_steps().len(),
            estimate: est.total,
            acquisition,
        });
        tracing::info!(
            steps = steps.len(),
            estimate_s = est.total.as_secs_f64(),
            bound_s = est.bound.as_secs_f64(),
            acquisition,
            "starting the schedule"
        );

        let t0 = Instant::now();
        let criteria = SettleCriteria {
            tolerance: self.plan.table().rate_tolerance_dps,
            relative_tolerance: 0.0,
            window: self.plan.table().stability_window,
            interval: self
                .options
                .sample_interval
                .min(self.plan.table().stability_window / 4),
            timeout: self.plan.table().at_rate_timeout,
        };
        let accel = self.plan.table().acceleration_dps2;
        let dwell = self.plan.settle();
        let ctx = StepContext {
            criteria,
            accel,
            dwell,
            reading_time,
        };
        self.start_warmup(&ctx).await?;
        let schedule_len = self.plan.schedule().len();
        let mut pending: Option<PendingFetch<M::Pending>> = None;
        // A step the table did not hold is measured again at once; the queue makes that (and
        // the session's step count) explicit.
        let mut queue: VecDeque<Step> = steps.iter().copied().collect();
        let mut retried: HashMap<usize, u32> = HashMap::new();
        let mut total = queue.len();
        let mut position = 0;
        while let Some(step) = queue.pop_front() {
            position += 1;
            // remaining: this step and every queued one, from the plan's estimate
            let cost = |s: &Step| {
                est.steps
                    .iter()
                    .find(|e| e.step.index == s.index)
                    .map_or(Duration::ZERO, |e| e.ramp + e.settle + e.acquire)
            };
            let after = queue.iter().map(cost).sum::<Duration>();
            self.emit(Event::StepStarted {
                step,
                number: step.index + 1,
                of: schedule_len,
                position,
                total,
                remaining: cost(&step) + after,
                after,
            });
            let last = queue.is_empty();
            let span = tracing::info_span!("step", index = step.index, rate_dps = step.rate_dps);
            let outcome = self
                .measure_step(&step, pending.take(), last, &ctx)
                .instrument(span)
                .await?;
            self.log_table_retries(Some(step.index))?;
            for lost in self.lost.drain(..) {
                queue.push_front(lost);
                total += 1;
            }
            match outcome {
                StepOutcome::Recorded => {}
                StepOutcome::Pending(p) => pending = Some(p),
                StepOutcome::Again { instrument, detail } => {
                    let used = retried.entry(step.index).or_default();
                    if *used >= self.options.step_retries {
                        return Err(SequenceError::NotHeld {
                            step: step.index,
                            rate_dps: step.rate_dps,
                            detail,
                        });
                    }
                    *used += 1;
                    self.log_retry(
                        Some(step.index),
                        instrument,
                        format!("step not recorded: {detail}; measuring it again"),
                    )?;
                    queue.push_front(step);
                    total += 1;
                }
            }
        }
        // park the table: the controlled stop; the wait for rest is the run's ending
        // (`bring_to_rest`), whatever way the run ends
        self.table.stop().await?;
        let elapsed = t0.elapsed();
        let bound = est.bound.as_secs_f64();
        let elapsed_s = elapsed.as_secs_f64();
        let ratio = if bound > 0.0 {
            elapsed_s / bound
        } else {
            f64::NAN
        };
        tracing::info!(bound_s = bound, elapsed_s, ratio, "schedule done");
        Ok(RunTiming {
            bound_s: bound,
            elapsed_s,
            ratio: if ratio.is_finite() { ratio } else { 1.0 },
            acquisition: Some(acquisition.into()),
        })
    }

    /// One step: demand the rate, (fetch the previous step's readings while the table ramps),
    /// wait until at rate, dwell, acquire, check the table held the rate, record (or hand the
    /// last memory burst back as pending, to be fetched during the next ramp).
    async fn measure_step(
        &mut self,
        step: &Step,
        pending: Option<PendingFetch<M::Pending>>,
        last: bool,
        ctx: &StepContext,
    ) -> Result<StepOutcome<PendingFetch<M::Pending>>, SequenceError> {
        let at_rate;
        if self.servo_off() || !self.plan.has_table() {
            // nothing to demand: the table is at rest with its servo off, or there is none
            at_rate = Instant::now();
            if let Some(p) = pending {
                self.emit(Event::Phase {
                    step: p.step.index,
                    phase: Phase::Fetching,
                });
                let fetched = self.dmm_mut()?.collect(p.pending).await;
                self.take_fetched(p.step, fetched, p.stats, p.t_start, p.t_end)?;
            }
            return self.acquire_step(step, at_rate, last, ctx).await;
        }
        self.moved = true;
        self.table.set_rate(step.rate_dps, ctx.accel).await?;
        self.emit(Event::Phase {
            step: step.index,
            phase: Phase::Ramping,
        });
        if let Some(p) = pending {
            // the previous step's readings come over while the table ramps
            self.emit(Event::Phase {
                step: p.step.index,
                phase: Phase::Fetching,
            });
            let Self { table, dmm, .. } = self;
            let dmm = dmm.as_mut().ok_or_else(released)?;
            // the dwell runs from the moment the table is at rate, fetch or no fetch
            let events = self.events.clone();
            let mut observe = move |p| {
                if let Some(tx) = &events {
                    let _ = tx.send(Event::Settle(p));
                }
            };
            let wait = table.wait_at_rate_observed(&ctx.criteria, &mut observe);
            let PendingFetch {
                step: p_step,
                pending: p_pending,
                stats: p_stats,
                t_start: p_start,
                t_end: p_end,
            } = p;
            let (settled, fetched) = tokio::join!(wait, dmm.collect(p_pending));
            // record the previous step before anything else can fail
            self.take_fetched(p_step, fetched, p_stats, p_start, p_end)?;
            at_rate = settled?.at_rate_since;
        } else {
            let events = self.events.clone();
            let mut observe = move |p| {
                if let Some(tx) = &events {
                    let _ = tx.send(Event::Settle(p));
                }
            };
            at_rate = self
                .table
                .wait_at_rate_observed(&ctx.criteria, &mut observe)
                .await?
                .at_rate_since;
        }
        self.acquire_step(step, at_rate, last, ctx).await
    }

    /// The rest of a step once the table is at its rate (since `at_rate`): dwell, acquire
    /// while watching the table, check the hold, record (or hand the readings back pending).
    async fn acquire_step(
        &mut self,
        step: &Step,
        at_rate: Instant,
        last: bool,
        ctx: &StepContext,
    ) -> Result<StepOutcome<PendingFetch<M::Pending>>, SequenceError> {
        // the settling dwell counts from the first sample of the stability window: the
        // table has held the rate since then
        let dwell_end = at_rate + ctx.dwell;
        if dwell_end > Instant::now() {
            self.emit(Event::Phase {
                step: step.index,
                phase: Phase::Settling,
            });
            let interval = self.options.sample_interval;
            self.table
                .record_while(interval, tokio::time::sleep_until(dwell_end))
                .await?;
        }
        self.emit(Event::Phase {
            step: step.index,
            phase: Phase::Acquiring,
        });
        let n = usize::try_from(step.sample_count(ctx.reading_time)).unwrap_or(usize::MAX);
        let may_defer = self.options.overlap_fetch && !last;
        self.progress_to_events();
        let t_start = self.now_s();
        let interval = self.options.sample_interval;
        let Self { table, dmm, .. } = self;
        let dmm = dmm.as_mut().ok_or_else(released)?;
        let (measured, mut stats) = table
            .record_while(interval, dmm.measure(n, may_defer))
            .await?;
        let measured = measured.map_err(dmm_error)?;
        let t_end = self.now_s();
        // the meter's recoveries are logged whatever the table did
        if let Measured::Complete(acq) = &measured {
            for note in &acq.notes {
                self.log_retry(Some(step.index), "dmm", note.clone())?;
            }
        }
        if self.plan.has_table()
            && let Some(why) = self.check_hold(step, &mut stats).await?
        {
            return Ok(StepOutcome::Again {
                instrument: "table",
                detail: why,
            });
        }
        match measured {
            Measured::Complete(acq) => {
                let Acquired {
                    readings, retries, ..
                } = acq;
                self.record(step, &readings, stats, retries, t_start, t_end)?;
                Ok(StepOutcome::Recorded)
            }
            Measured::Pending(pending) => Ok(StepOutcome::Pending(PendingFetch {
                step: *step,
                pending,
                stats,
                t_start,
                t_end,
            })),
        }
    }

    /// The table's side of a finished acquisition, checked before its readings are accepted:
    /// one more sample right after the last reading (a latched fault or an opened interlock
    /// is an error there, as in every sample), the mode, and every sample of the acquisition
    /// against the demand. `Ok(None)`: the table held the rate; `Ok(Some(why))`: it did not,
    /// the step must not be recorded but the table is still in RATE mode (the step may be
    /// measured again); `Err`: the table faulted or left RATE mode, and the run ends.
    /// `stats` gains the final sample.
    async fn check_hold(
        &mut self,
        step: &Step,
        stats: &mut RateStats,
    ) -> Result<Option<String>, SequenceError> {
        let end = self.table.sample().await?;
        *stats = merge_stats(&[*stats, RateStats::from_samples(&[end])]);
        let status = self.table.status().await?;
        let demand = step.rate_dps;
        let (expected, name) = if self.servo_off() {
            (TableMode::Off, "OFF (servo off)")
        } else {
            (TableMode::Rate, "RATE")
        };
        if status.mode != expected {
            return Err(SequenceError::NotHeld {
                step: step.index,
                rate_dps: demand,
                detail: format!(
                    "the table left {name} mode during the acquisition (now {:?}, measured {end:+.6} °/s)",
                    status.mode
                ),
            });
        }
        let tol = self.plan.table().rate_tolerance_dps;
        let hold = tol * self.options.hold_tolerance_factor;
        let farthest = if (stats.min - demand).abs() > (stats.max - demand).abs() {
            stats.min
        } else {
            stats.max
        };
        if !(stats.count > 0 && (farthest - demand).abs() <= hold) {
            return Ok(Some(format!(
                "the measured rate reached {farthest:+.6} °/s during the acquisition (demand \
                 {demand:+} °/s, allowed ±{hold} °/s; {} table samples)",
                stats.count
            )));
        }
        if (stats.mean - demand).abs() > tol {
            return Ok(Some(format!(
                "the mean measured rate during the acquisition was {:+.6} °/s (demand {demand:+} \
                 °/s, tolerance ±{tol} °/s; {} table samples)",
                stats.mean, stats.count
            )));
        }
        Ok(None)
    }

    /// The table driver's link retries (a lost or garbled reply asked again) go to the
    /// manifest like the meter's.
    fn log_table_retries(&mut self, step: Option<usize>) -> Result<(), RunError> {
        for note in self.table.take_retries() {
            self.log_retry(step, "table", note)?;
        }
        Ok(())
    }

    fn dmm_mut(&mut self) -> Result<&mut M, SequenceError> {
        self.dmm.as_mut().ok_or_else(released)
    }

    fn progress_to_events(&mut self) {
        let tx = self.events.clone();
        if let Some(dmm) = self.dmm.as_mut() {
            dmm.set_progress(tx.map(|tx| {
                // Welford's running mean and variance of the step's valid readings
                let (mut n, mut mean, mut m2) = (0u64, 0.0f64, 0.0f64);
                Box::new(move |p: gyrocal_meter::Progress| {
                    if p.done <= 1 {
                        (n, mean, m2) = (0, 0.0, 0.0);
                    }
                    let latest = p.latest.volts();
                    if let Some(v) = latest {
                        n += 1;
                        let d = v - mean;
                        mean += d / n as f64;
                        m2 += d * (v - mean);
                    }
                    let _ = tx.send(Event::Acquiring {
                        done: p.done,
                        total: p.total,
                        latest,
                        mean: if n > 0 { mean } else { f64::NAN },
                        std: (n > 1).then(|| (m2 / (n - 1) as f64).sqrt()),
                    });
                }) as gyrocal_meter::ProgressFn
            }));
        }
    }

    /// The previous step's readings fetched from the meter's memory: recorded, or, when the
    /// meter lost them (a power cycle), queued to be measured again right after this step.
    fn take_fetched(
        &mut self,
        step: Step,
        fetched: Result<Acquired, M::Error>,
        stats: RateStats,
        t_start: f64,
        t_end: f64,
    ) -> Result<(), SequenceError> {
        match fetched {
            Ok(acq) => self.record_acquired(&step, acq, stats, t_start, t_end),
            Err(e) => {
                let e = dmm_error(e);
                if !readings_lost(&e) {
                    return Err(e);
                }
                let times = self.lost_count.entry(step.index).or_default();
                *times += 1;
                if *times > self.options.lost_retries {
                    let attempts = *times;
                    let SequenceError::Dmm(last) = e else {
                        return Err(e);
                    };
                    return Err(SequenceError::ReadingsLostAgain {
                        step: step.index,
                        rate_dps: step.rate_dps,
                        attempts,
                        last,
                    });
                }
                self.log_retry(
                    Some(step.index),
                    "dmm",
                    format!(
                        "{e}; step {} is measured again after this one",
                        step.index + 1
                    ),
                )?;
                self.lost.push(step);
                Ok(())
            }
        }
    }

    /// Logs the recoveries of a collected transfer and writes the step.
    fn record_acquired(
        &mut self,
        step: &Step,
        acq: Acquired,
        stats: RateStats,
        t_start: f64,
        t_end: f64,
    ) -> Result<(), SequenceError> {
        for note in acq.notes {
            self.log_retry(Some(step.index), "dmm", note)?;
        }
        self.record(step, &acq.readings, stats, acq.retries, t_start, t_end)
    }

    /// Writes a complete step: samples (flushed), then the step row (fsynced).
    fn record(
        &mut self,
        step: &Step,
        readings: &[Reading],
        stats: RateStats,
        retries: u32,
        t_start: f64,
        t_end: f64,
    ) -> Result<(), SequenceError> {
        let n = readings.len();
        // Reading times are spread evenly over the acquisition: the meter paces them itself.
        let samples: Vec<Sample> = readings
            .iter()
            .enumerate()
            .map(|(i, r)| Sample {
                index: i as u64,
                t_s: t_start + (t_end - t_start) * (i as f64 + 1.0) / n.max(1) as f64,
                volts: r.volts(),
            })
            .collect();
        self.run.append_samples(step.index, &samples)?;
        let volts: Vec<f64> = readings.iter().filter_map(|r| r.volts()).collect();
        let overloads = (n - volts.len()) as u64;
        if volts.is_empty() {
            return Err(SequenceError::AllOverloaded {
                step: step.index,
                rate_dps: step.rate_dps,
                count: n,
            });
        }
        let (mean, std) = mean_std(&volts);
        let measured = stats.count > 0 && stats.mean.is_finite();
        let rec = StepRecord {
            step: step.index,
            pass: step.pass,
            rate_dps: step.rate_dps,
            rate_meas_dps: measured.then_some(stats.mean),
            rate_meas_std_dps: (measured && stats.std.is_finite()).then_some(stats.std),
            rate_meas_min_dps: measured.then_some(stats.min),
            rate_meas_max_dps: measured.then_some(stats.max),
            rate_samples: measured.then_some(stats.count),
            volts: mean,
            volts_std: std,
            n: volts.len() as u64,
            overloads,
            retries,
            t_start_s: t_start,
            t_end_s: t_end,
        };
        if overloads > 0 {
            tracing::warn!(
                step = step.index,
                overloads,
                "overload readings excluded from the mean"
            );
        }
        self.run.append_step(rec.clone())?;
        let elapsed = self.now_s();
        self.run.set_elapsed(elapsed)?;
        self.recorded += 1;
        self.emit(Event::StepDone(rec));
        if self.plan.kind() == PlanKind::Drift {
            self.watch_record(step, &volts, t_start, t_end)?;
        }
        Ok(())
    }

    /// A drift record with `[drift] table = "servo_off"`.
    fn servo_off(&self) -> bool {
        self.plan.kind() == PlanKind::Drift && self.plan.drift().table == TableRole::ServoOff
    }

    /// The warm-up of this session, when the plan has one and no earlier session completed
    /// it: before a sweep, a phase of its own at 0 °/s now; in a drift record, watched in the
    /// record's first segments (see [`Sequencer::watch_record`]).
    async fn start_warmup(&mut self, ctx: &StepContext) -> Result<(), SequenceError> {
        let Some(settings) = self.plan.warmup().copied() else {
            return Ok(());
        };
        if let Some(done) = self.run.manifest().warmup.as_ref().filter(|w| w.complete) {
            tracing::info!(
                time_s = done.time_s,
                "warm-up completed in an earlier session: not repeated"
            );
            return Ok(());
        }
        let period = ctx.reading_time.as_secs_f64();
        if self.plan.kind() == PlanKind::Drift {
            self.warmup = Some(WarmupWatch::new(
                &settings,
                period,
                self.now_s(),
                monitor::WARMUP_IN_RECORD,
            ));
            return Ok(());
        }
        // before the sweep: the table holds 0 °/s while the readings settle
        self.moved = true;
        self.table.set_rate(0.0, ctx.accel).await?;
        let events = self.events.clone();
        let mut observe = move |p| {
            if let Some(tx) = &events {
                let _ = tx.send(Event::Settle(p));
            }
        };
        self.table
            .wait_at_rate_observed(&ctx.criteria, &mut observe)
            .await?;
        let mut watch = WarmupWatch::new(
            &settings,
            period,
            self.now_s(),
            monitor::WARMUP_BEFORE_SWEEP,
        );
        tracing::info!(window = watch.window(), "warm-up before the sweep");
        self.run.set_warmup(watch.record().clone())?;
        self.emit(Event::Warmup(watch.record().clone()));
        let n = usize::try_from(watch.window()).unwrap_or(usize::MAX);
        let interval = self.options.sample_interval;
        loop {
            let t_start = self.now_s();
            let Self { table, dmm, .. } = self;
            let dmm = dmm.as_mut().ok_or_else(released)?;
            let (measured, _stats) = table.record_while(interval, dmm.measure(n, false)).await?;
            let acq = match measured.map_err(dmm_error)? {
                Measured::Complete(acq) => acq,
                Measured::Pending(p) => self.dmm_mut()?.collect(p).await.map_err(dmm_error)?,
            };
            let t_end = self.now_s();
            for note in &acq.notes {
                self.log_retry(None, "dmm", format!("warm-up: {note}"))?;
            }
            let volts: Vec<f64> = acq.readings.iter().filter_map(|r| r.volts()).collect();
            let ended = watch.push(&volts, t_start, t_end);
            self.run.set_warmup(watch.record().clone())?;
            self.run.set_elapsed(t_end)?;
            self.emit(Event::Warmup(watch.record().clone()));
            if ended {
                tracing::info!(time_s = watch.record().time_s, "warm-up complete");
                return Ok(());
            }
        }
    }

    /// A drift segment's readings: the running deviation, and the warm-up while it lasts.
    fn watch_record(
        &mut self,
        step: &Step,
        volts: &[f64],
        t_start: f64,
        t_end: f64,
    ) -> Result<(), SequenceError> {
        let period = (t_end - t_start) / volts.len().max(1) as f64;
        let adev = self.adev.get_or_insert_with(|| AdevWatch::new(period));
        adev.push(volts);
        let shown = adev.shown();
        let readings = adev.readings();
        if let Some(w) = self.warmup.as_mut()
            && !w.is_complete()
        {
            w.push(volts, t_start, t_end);
            let rec = w.record().clone();
            self.run.set_warmup(rec.clone())?;
            self.emit(Event::Warmup(rec));
        }
        self.emit(Event::Drift {
            segment: step.index + 1,
            of: self.plan.step_count(),
            readings,
            elapsed_s: t_end,
            adev_v: shown,
        });
        Ok(())
    }
}

fn released() -> SequenceError {
    SequenceError::Dmm(Box::new(Released))
}

/// The multimeter was used after the sequencer handed it back (a bug).
#[derive(Debug, thiserror::Error)]
#[error("multimeter already released")]
struct Released;

impl MeterError for Released {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// The meter gave no timing model after its configuration (a bug in its driver).
#[derive(Debug, thiserror::Error)]
#[error("the multimeter has no timing model after its configuration")]
struct NoTiming;

impl MeterError for NoTiming {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// The meter lost readings it still held (a power cycle): the step must be measured again.
fn readings_lost(e: &SequenceError) -> bool {
    matches!(e, SequenceError::Dmm(d) if d.kind() == ErrorKind::ReadingsLost)
}

/// The message of a caught panic.
fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// Mean and sample standard deviation (`None` for one value).
fn mean_std(v: &[f64]) -> (f64, Option<f64>) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (mean, None);
    }
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, Some(var.sqrt()))
}

/// Pools the statistics of several recordings.
fn merge_stats(parts: &[RateStats]) -> RateStats {
    let parts: Vec<&RateStats> = parts.iter().filter(|s| s.count > 0).collect();
    let count: u64 = parts.iter().map(|s| s.count).sum();
    if count == 0 {
        return RateStats::EMPTY;
    }
    let n = count as f64;
    let mean = parts.iter().map(|s| s.mean * s.count as f64).sum::<f64>() / n;
    // pooled sum of squares about the overall mean
    let ss: f64 = parts
        .iter()
        .map(|s| {
            let within = if s.count > 1 && s.std.is_finite() {
                s.std.powi(2) * (s.count as f64 - 1.0)
            } else {
                0.0
            };
            within + s.count as f64 * (s.mean - mean).powi(2)
        })
        .sum();
    let std = if count > 1 {
        (ss / (n - 1.0)).sqrt()
    } else {
        f64::NAN
    };
    RateStats {
        count,
        mean,
        std,
        min: parts.iter().map(|s| s.min).fold(f64::INFINITY, f64::min),
        max: parts
            .iter()
            .map(|s| s.max)
            .fold(f64::NEG_INFINITY, f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_stats_equal_stats_of_all_samples() {
        let a = [1.0, 2.0, 3.0];
        let b = [10.0, 11.0];
        let all: Vec<f64> = a.iter().chain(b.iter()).copied().collect();
        let m = merge_stats(&[RateStats::from_samples(&a), RateStats::from_samples(&b)]);
        let want = RateStats::from_samples(&all);
        assert_eq!(m.count, want.count);
        assert!((m.mean - want.mean).abs() < 1e-12);
        assert!((m.std - want.std).abs() < 1e-12);
        assert_eq!((m.min, m.max), (1.0, 11.0));
    }

    #[test]
    fn mean_std_of_one_value_has_no_std() {
        assert_eq!(mean_std(&[2.5]), (2.5, None));
        let (m, s) = mean_std(&[1.0, 3.0]);
        assert_eq!(m, 2.0);
        assert!((s.unwrap() - 2f64.sqrt()).abs() < 1e-12);
    }
}
