//! # gyrocal-meter
//!
//! The multimeter role: what a calibration run needs from a DC voltmeter, whatever the model
//! and the link. The sequencer is generic over [`Multimeter`]; the CLI chooses the meter from
//! the plan (the edge), as ripgrep chooses its matcher and hands it to a generic search.
//!
//! Why a role and not the driver: a run's logic (measure while the table holds the rate, let a
//! transfer overlap the next ramp, retry on a timeout, re-measure readings the meter lost) is
//! the same for every meter; what differs (a 512-reading memory fetched in bursts, a 50,000-
//! reading memory drained while it fills, streaming over RS-232) is the meter's business, behind
//! [`Multimeter::measure`] and [`Multimeter::collect`].
//!
//! Errors expose a [`ErrorKind`] through [`MeterError::kind`], in the manner of embedded-hal's
//! `Error::kind()`: generic code decides on kinds (retry a [`ErrorKind::Timeout`], measure again
//! after [`ErrorKind::ReadingsLost`]) without knowing the backend. The one [`ErrorKind`] is
//! every meter driver's: a driver's own `kind()` (the 34401A's) tells more apart
//! ([`ErrorKind::Identity`], [`ErrorKind::Config`], [`ErrorKind::Io`]) than the role reports
//! ([`ErrorKind::in_role`]).
//!
//! The SCPI basics the SCPI meters share (an error-queue entry, its parser, reading the queue
//! until it is empty) are in [`scpi`], written once and without I/O.

mod late;
pub mod scpi;

pub use late::LateReplies;
pub use scpi::{InstrumentError, parse_error};

use std::future::Future;
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// The value meters send for an overload (`+9.90000000E+37`, or negative).
pub const OVERLOAD: f64 = 9.9e37;

/// One reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Reading {
    /// A voltage, in volts.
    Volts(f64),
    /// The input was beyond the range (the meter sent ±9.9E37). Never a number to average.
    Overload {
        /// True for +9.9E37, false for -9.9E37.
        positive: bool,
    },
}

impl Reading {
    /// The voltage, or `None` for an overload.
    pub fn volts(self) -> Option<f64> {
        match self {
            Reading::Volts(v) => Some(v),
            Reading::Overload { .. } => None,
        }
    }

    /// True for an overload.
    pub fn is_overload(self) -> bool {
        matches!(self, Reading::Overload { .. })
    }
}

/// What kind of failure, for callers that decide without knowing the meter. One enum for
/// every meter: a driver maps its errors onto it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// No (complete) reply in time. Retryable after a recovery.
    Timeout,
    /// The link went away. Not retryable without reopening it.
    Disconnected,
    /// A reply the protocol does not allow. Retryable after a recovery.
    Garbled,
    /// The meter reported errors (its error queue).
    Instrument,
    /// Readings still in the meter were lost (a power cycle): measure them again.
    ReadingsLost,
    /// The meter stopped answering and did not come back in time.
    Unreachable,
    /// An operating-system error on the link. The role reports it as [`ErrorKind::Other`].
    Io,
    /// The device is not the meter the plan names. The role reports it as
    /// [`ErrorKind::Other`].
    Identity,
    /// Settings or a request refused before anything was sent (or an acquisition before the
    /// configuration). The role reports it as [`ErrorKind::Other`].
    Config,
    /// Anything else: a failure after the driver's own retries (it gave up), a refused
    /// identity or configuration, an I/O error, a bug.
    Other,
}

impl ErrorKind {
    /// The kind as the role reports it ([`MeterError::kind`]): a run stops alike on a refused
    /// identity, a refused configuration and an I/O error, so they are [`ErrorKind::Other`];
    /// the other kinds are themselves. Drivers map their errors onto the detailed kind and
    /// report it through this, so both meters classify alike.
    pub fn in_role(self) -> ErrorKind {
        match self {
            ErrorKind::Io | ErrorKind::Identity | ErrorKind::Config => ErrorKind::Other,
            k => k,
        }
    }

    /// Whether a recovery and a retry of the same exchange may succeed.
    pub fn is_retryable(self) -> bool {
        matches!(self, ErrorKind::Timeout | ErrorKind::Garbled)
    }
}

/// A meter's error: a message naming the device, and a kind.
pub trait MeterError: std::error::Error + Send + Sync + 'static {
    /// The kind of failure, as the role reports it (see [`ErrorKind::in_role`]); a failure
    /// after the driver's own retries is [`ErrorKind::Other`] (not retryable again).
    fn kind(&self) -> ErrorKind;
}

/// The meter's identity, from `*IDN?` (or the model's own query).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// The reply as received.
    pub raw: String,
    /// Manufacturer.
    pub manufacturer: String,
    /// Model.
    pub model: String,
    /// Serial number (`0` on a 34401A).
    pub serial: String,
    /// Firmware version.
    pub version: String,
}

/// DC voltage settings a plan asks for; each meter checks them against its own facts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DcVolts {
    /// Fixed range, volts (`None`: autorange).
    pub range_v: Option<f64>,
    /// Integration time, power-line cycles.
    pub nplc: f64,
    /// Autozero on.
    pub autozero: bool,
    /// Mains frequency, Hz.
    pub line_hz: u32,
}

/// Readings taken, with what it cost to get them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Acquired {
    /// Every reading, in order, overloads included.
    pub readings: Vec<Reading>,
    /// Recoveries needed (each followed by a retry of the failed part).
    pub retries: u32,
    /// What each recovery was and did, for the run's manifest.
    pub notes: Vec<String>,
}

impl Acquired {
    /// Appends `other` (a later part of the same step).
    pub fn extend(&mut self, other: Acquired) {
        self.readings.extend(other.readings);
        self.retries += other.retries;
        self.notes.extend(other.notes);
    }
}

/// The outcome of [`Multimeter::measure`].
#[derive(Debug)]
pub enum Measured<P> {
    /// Every reading is here.
    Complete(Acquired),
    /// Every reading was taken, the last of them are still in the meter: hand the value to
    /// [`Multimeter::collect`] (meanwhile the table may move: the meter is not measuring).
    Pending(P),
}

/// What acquiring `n` readings costs, from a meter's timing model (see [`TimingModel::cost`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Cost {
    /// Expected time the step spends acquiring: commands, arming, the readings and every
    /// transfer the step waits for (all of them unless `deferred`).
    pub in_step: Duration,
    /// Expected time of the transfer left in the meter ([`Measured::Pending`]), which overlaps
    /// the table's next ramp; zero when nothing is deferred.
    pub deferred: Duration,
    /// The physical bound of the step's acquisition, what no sequencer can beat: arming, the
    /// readings (or the wire, when it is the slower), and the transfer that tells the host
    /// the last reading was taken (the table must not move before that). Commands and
    /// protocol overhead are not in it.
    pub bound: Duration,
    /// The physical bound of the deferred transfer (zero when nothing is deferred).
    pub bound_deferred: Duration,
}

/// A meter's timing model at fixed settings: how long readings take and what acquiring them
/// costs. Public so a planner can estimate a run before any instrument is connected; each
/// meter's crate owns its model (integration, trigger delay, arming, wire).
pub trait TimingModel: Send + Sync {
    /// One reading's time.
    fn reading_time(&self) -> Duration;
    /// How the meter acquires at these settings, in a word (`stream`, `memory`, ...), for the
    /// run's log and timing record.
    fn acquisition(&self) -> &'static str;
    /// What `n` readings cost; with `defer`, the part the meter may hand over as
    /// [`Measured::Pending`] is counted apart (the caller overlaps it with the next ramp).
    fn cost(&self, n: usize, defer: bool) -> Cost;
}

/// Progress of a measurement, after each reading received.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Readings received so far in this measurement.
    pub done: usize,
    /// Readings asked for.
    pub total: usize,
    /// The reading just received.
    pub latest: Reading,
}

/// A progress callback (see [`Multimeter::set_progress`]).
pub type ProgressFn = Box<dyn FnMut(Progress) + Send>;

/// A DC voltmeter, whatever its model and link. Methods take `&mut self`: one task owns it.
pub trait Multimeter: Send {
    /// The meter's error.
    type Error: MeterError;
    /// Readings taken and still in the instrument (see [`Measured::Pending`]).
    type Pending: Send;

    /// The link's description, used in messages.
    fn describe(&self) -> &str;

    /// Clears the link, takes remote control, identifies the meter (refusing another model),
    /// resets it to a known state.
    fn connect(&mut self) -> impl Future<Output = Result<Identity, Self::Error>> + Send;

    /// Configures DC volts (checked against the meter's own limits before anything is sent).
    fn configure(
        &mut self,
        settings: &DcVolts,
    ) -> impl Future<Output = Result<(), Self::Error>> + Send;

    /// The meter's timing model at the configured settings (`None` before
    /// [`Multimeter::configure`]): the run's estimate, its physical bound and the number of
    /// readings a whole-revolution step takes come from it.
    fn timing(&self) -> Option<Box<dyn TimingModel>>;

    /// Takes `n` readings. With `may_defer`, the meter may answer [`Measured::Pending`] once
    /// every reading is taken but some are still in its memory, so the caller can move the
    /// table during their transfer. Recoveries and retries happen inside, up to the meter's
    /// limit, and are reported in [`Acquired`].
    fn measure(
        &mut self,
        n: usize,
        may_defer: bool,
    ) -> impl Future<Output = Result<Measured<Self::Pending>, Self::Error>> + Send;

    /// Transfers pending readings (retrying a garbled transfer). An error of kind
    /// [`ErrorKind::ReadingsLost`] means the meter lost them: measure them again.
    fn collect(
        &mut self,
        pending: Self::Pending,
    ) -> impl Future<Output = Result<Acquired, Self::Error>> + Send;

    /// After an interrupted exchange: brings the meter back to a known state (device clear,
    /// and a full re-establish if it lost its settings). Returns what was done, for the log.
    fn recover(&mut self) -> impl Future<Output = Result<String, Self::Error>> + Send;

    /// Hands the meter back to its front panel.
    fn release(&mut self) -> impl Future<Output = Result<(), Self::Error>> + Send;

    /// Calls `progress` with every reading received (`None` removes it).
    fn set_progress(&mut self, progress: Option<ProgressFn>);
}
