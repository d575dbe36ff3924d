//! How a run ends: what the operator asked for ([`StopRequest`]), where the table was left
//! ([`TableRest`]), why a run did not complete ([`SequenceError`]) and the summary
//! ([`RunSummary`]); and the engine's tunables ([`SequencerOptions`]).

use std::time::Duration;

use gyrocal_chamber::ChamberError;
use gyrocal_meter::MeterError;
use gyrocal_table::TableError;

use crate::sink::SinkError;
use gyrocal_files::rundir::{RunError, Status, Timing as RunTiming};

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

/// Where the thermal chamber was left at the end of a run: its safe state read back, or
/// plainly not confirmed (like the table's [`TableRest`]).
#[derive(Debug, Clone, PartialEq)]
pub enum ChamberRest {
    /// The run has no chamber.
    NoChamber,
    /// The chamber was read back in its safe state.
    Confirmed {
        /// The state, in words (`setpoint 23 °C (ambient), in control`).
        state: String,
        /// What was read back.
        detail: String,
    },
    /// The safe state was asked for but could NOT be confirmed (a silent controller, a
    /// setpoint read back wrong, an option the chamber was not set up for).
    NotConfirmed {
        /// The state asked for, in words.
        state: String,
        /// Why it could not be confirmed.
        reason: String,
    },
}

impl ChamberRest {
    /// True when no chamber can be left hot or cold: confirmed safe, or none in the run.
    pub fn is_safe(&self) -> bool {
        matches!(self, ChamberRest::NoChamber | ChamberRest::Confirmed { .. })
    }

    /// The ending's line: `chamber: setpoint 23 °C (ambient), in control: confirmed`, or
    /// `chamber: standby could NOT be confirmed: <why>`; `None` without a chamber.
    pub fn line(&self) -> Option<String> {
        match self {
            ChamberRest::NoChamber => None,
            ChamberRest::Confirmed { state, .. } => Some(format!("chamber: {state}: confirmed")),
            ChamberRest::NotConfirmed { state, reason } => Some(format!(
                "chamber: {state} could NOT be confirmed: {reason}; check the chamber by hand"
            )),
        }
    }
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
    /// A consumer of the run's results other than the run directory failed (see
    /// [`crate::sink`]).
    #[error("{0}")]
    Sink(Box<SinkError>),
    /// The sequencer panicked (a bug); the table was still brought to rest.
    #[error("internal error (panic) in the sequencer: {0}")]
    Panicked(String),
    /// The thermal chamber failed (silent, refused a setpoint, a broken link) after its
    /// driver's own retries.
    #[error("chamber: {0}")]
    Chamber(Box<ChamberError>),
    /// The chamber raised an alarm: the run stops with the table at rest, the step in
    /// progress not recorded; resumable once the alarm is dealt with.
    #[error(
        "chamber alarm: {}{}; the run is stopped (resume it once the alarm is cleared at the chamber)",
        alarms.join(", "),
        step.map(|s| format!(" during step {}, which is not recorded", s + 1)).unwrap_or_default()
    )]
    ChamberAlarm {
        /// The alarms the chamber reported.
        alarms: Vec<String>,
        /// The step in progress (0-based), if any.
        step: Option<usize>,
    },
    /// A temperature of the series did not soak within `[series] max_wait_min`.
    #[error(
        "temperature {} of the series ({setpoint_c} °C) not soaked after {waited_min:.1} min (max_wait_min): the gyro read {} (band ±{band_c} °C{}); check the chamber and the gyro's sensor, or widen the band or the wait",
        .point + 1,
        product_c.map_or("nothing".to_string(), |t| format!("{t} °C")),
        rate_c_per_min.map_or(String::new(), |r| format!(", changing {r:.3} °C/min, limit {stability_c_per_min} °C/min"))
    )]
    NotSoaked {
        /// 0-based index into `[series] temperatures_c`.
        point: u32,
        /// The target, °C.
        setpoint_c: f64,
        /// The gyro's last temperature, °C.
        product_c: Option<f64>,
        /// The band, ± °C.
        band_c: f64,
        /// Its last rate of change, °C/min.
        rate_c_per_min: Option<f64>,
        /// The stability limit, °C/min.
        stability_c_per_min: f64,
        /// How long the soak waited, min.
        waited_min: f64,
    },
}

/// What kind of ending a [`SequenceError`] is, for a caller that decides on it (an exit code,
/// a retry policy) without matching the variants' contents.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceErrorKind {
    /// The multimeter failed.
    Meter,
    /// The rate table failed or faulted.
    Table,
    /// The run directory could not be written.
    RunDir,
    /// Another consumer of the results failed.
    Sink,
    /// The plan must change (every reading overloaded) or the bench does not match the
    /// recorded data (simulated vs measured): a new run.
    Plan,
    /// A step could not be recorded within its bounded repeats (the table did not hold, or
    /// the meter lost its readings every time).
    RepeatsSpent,
    /// The operator or a signal stopped the run.
    Stopped,
    /// A bug (a panic).
    Internal,
    /// The chamber failed, raised an alarm, or a temperature did not soak in time.
    Chamber,
}

impl SequenceError {
    /// What kind of ending this is.
    pub fn kind(&self) -> SequenceErrorKind {
        match self {
            SequenceError::Dmm(_) => SequenceErrorKind::Meter,
            SequenceError::Table(_) => SequenceErrorKind::Table,
            SequenceError::RunDir(_) => SequenceErrorKind::RunDir,
            SequenceError::Sink(_) => SequenceErrorKind::Sink,
            SequenceError::AllOverloaded { .. } | SequenceError::Mixed { .. } => {
                SequenceErrorKind::Plan
            }
            SequenceError::NotHeld { .. } | SequenceError::ReadingsLostAgain { .. } => {
                SequenceErrorKind::RepeatsSpent
            }
            SequenceError::Stopped(_) => SequenceErrorKind::Stopped,
            SequenceError::Panicked(_) => SequenceErrorKind::Internal,
            SequenceError::Chamber(_)
            | SequenceError::ChamberAlarm { .. }
            | SequenceError::NotSoaked { .. } => SequenceErrorKind::Chamber,
        }
    }
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
pub(crate) fn dmm_error<E: MeterError>(e: E) -> SequenceError {
    SequenceError::Dmm(Box::new(e))
}

impl From<TableError> for SequenceError {
    fn from(e: TableError) -> Self {
        SequenceError::Table(Box::new(e))
    }
}

impl From<ChamberError> for SequenceError {
    fn from(e: ChamberError) -> Self {
        SequenceError::Chamber(Box::new(e))
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
    /// Where the chamber was left, as far as gyrocal could confirm (after the table).
    pub chamber: ChamberRest,
    /// Whether resuming the same plan can complete the run. False when the plan itself must
    /// change (every reading of a step overloaded: the range is too small), which makes it
    /// another plan: a new run.
    pub resumable: bool,
    /// An emergency stop was sent (by a second signal, after a table fault, or because the
    /// controlled stop could not be sent): the table's interlock is open and must be re-armed
    /// at the table before the run is resumed.
    pub emergency_stop: bool,
}

impl From<SinkError> for SequenceError {
    fn from(e: SinkError) -> Self {
        match e {
            SinkError::RunDir(e) => SequenceError::RunDir(Box::new(e)),
            other => SequenceError::Sink(Box::new(other)),
        }
    }
}
