//! # gyrocal-table
//!
//! The rate-table role: the [`RateTable`] trait a calibration sequencer programs against, and
//! one generic implementation of it ([`Table`]) over any wire protocol ([`Dialect`]), generic
//! over any [`gyrocal_link::Transport`]. The dialects live in crates of their own
//! (`gyrocal-acl` for the ACUTROL command language, `gyrocal-aerosmith` for the experimental
//! Ideal Aerosmith one), so code written against the role (the sequencer) depends on no
//! driver.
//!
//! ## Policy once, dialects small
//!
//! Everything listed below except the bytes is the same for every rate table, so it is written
//! once, in [`Table<D: Dialect>`](Table), and a dialect implements only its wire protocol:
//! identify, servo on, demand a rate with an acceleration, read rate, position and mode, poll
//! for a latched fault, controlled and emergency stop, plus its retries of idempotent queries
//! (see [`dialect`]). This is probe-rs's pattern for JTAG (`impl<P: AutoImplementJtagAccess>
//! JtagAccess for P` over a small `RawJtagIo` trait): a new probe implements the raw operations
//! and inherits the rest, so a fix to the policy fixes every table, and a second dialect cannot
//! forget the heartbeat or the rest check. `gyrocal_acl::AclTable<T>` is `Table<gyrocal_acl::Acl<T>>`, and
//! `AclTable::new(transport, config)` builds it as before.
//!
//! ## Why a driver and not a few `send_line` calls
//!
//! A scale-factor calibration is only as good as the rate actually applied, and a table turning
//! at 20 °/s with a gyro on it must stop safely whatever goes wrong. Lab scripts typically send a
//! rate, sleep a fixed time and leave the table spinning on an exception. This crate instead:
//!
//! - **refuses before sending**: rates above the client-side maximum and accelerations outside
//!   `(0, max]` are [`TableErrorKind::Limit`] errors and no byte goes out (an ACUTROL refuses an
//!   acceleration limit of 0 only after it was sent, and a table that takes it would never move);
//! - **reads the table's error queue** after every command batch and surfaces the table's own
//!   text ([`TableError::Table`]), so "Interlock open" is not silently ignored;
//! - **keeps an explicit state** ([`TableState`]) and handles mode prerequisites itself (a rate
//!   demand after a controlled stop re-enters RATE mode first; a latched fault must be cleared by
//!   an explicit [`RateTable::enable`]);
//! - **decides "at rate" from data** ([`RateTable::wait_at_rate`]): at least the ramp time
//!   `|Δω|/a`, then the measured rate inside a tolerance for a whole stability window; a timeout
//!   is a fault. "Profile complete" on the table only means the *command* reached the demand;
//! - **records what the table did**: the measured rate while waiting and while the multimeter
//!   acquires ([`RateTable::record_while`], or [`RateTable::start_recording`] /
//!   [`RateTable::sample`] / [`RateTable::stop_recording`]), as [`RateStats`];
//! - **has stop paths usable from anywhere**: [`RateTable::stop`] (`:Mode:Off 1`, a smooth
//!   controlled stop) and [`RateTable::emergency_stop`] (`:Interlock:Open 1`), both idempotent
//!   and usable after any error, and a cloneable [`StopHandle`] for signal handlers and other
//!   tasks, with a [`StopGuard`] that stops the table if a scope unwinds;
//! - **treats silence as a fault**: every sample is also a heartbeat with a deadline, and
//!   [`RateTable::heartbeat`] polls an idle table; a table that stops answering moves the driver
//!   to [`TableState::Faulted`] after a best-effort controlled stop;
//! - **rides out a flaky link without hiding it**: a query whose reply is lost, garbled or
//!   prefixed by line noise is asked again (queries only read state; commands are never
//!   repeated), within the same deadline, so a silent table is still a fault in time; every
//!   retry is logged and handed to the sequencer for the run manifest
//!   ([`RateTable::take_retries`]);
//! - **means rest when it says rest**: [`RateTable::wait_stopped`] returns only when the
//!   measured rate is near zero *and* the controller is in OFF mode (a rate passing through zero
//!   while reversing is not rest), bounded by [`RateTable::stop_deadline`], and reports what it
//!   saw ([`RestReport`]).
//!
//! The multimeter is on another port, so the sequencer polls the table concurrently with an
//! acquisition: `table.record_while(interval, dmm.read(500))` runs both in one task.
//!
//! A second dialect (Ideal Aerosmith ASCII, a binary framed table) is a new module implementing
//! [`Dialect`]; the table type, the sequencer and the tests of the policy stay as they are.

pub mod ask;
mod error;
pub mod latency;
mod none;
mod stats;
mod stop;
mod table;

pub mod dialect;

pub use dialect::Dialect;
pub use error::{TableError, TableErrorKind};
pub use none::{NO_TABLE, NoTable};
pub use stats::{RateAccumulator, RateStats};
pub use stop::{StopGuard, StopHandle, StopKind, StopPath};
pub use table::{PolicyConfig, Table};

use std::fmt;
use std::future::Future;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio::time::Instant;

/// Where the driver believes the table is. Transitions happen only inside the driver.
///
/// ```text
/// Disconnected --connect--> Connected --enable--> Servoed --set_rate--> Ramping
/// Ramping --wait_at_rate--> AtRate --set_rate--> Ramping
/// Servoed|Ramping|AtRate --stop/emergency_stop--> Stopping --wait_stopped--> Servoed|Connected
/// any --fault, settle timeout, lost heartbeat--> Faulted --enable--> Servoed
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TableState {
    /// Not yet identified.
    Disconnected,
    /// Identified; the servo may be off (interlock open) and faults may be latched.
    Connected,
    /// Interlock closed, servo on, not moving on command.
    Servoed,
    /// A rate demand was sent; the table has not been shown to be at rate.
    Ramping {
        /// The demanded rate, deg/s.
        target: f64,
    },
    /// The measured rate stayed inside the tolerance of the demand for a stability window.
    AtRate {
        /// The demanded rate, deg/s.
        rate: f64,
    },
    /// A controlled or emergency stop was sent; the table may still be decelerating.
    Stopping,
    /// A latched table fault, a settle timeout or a silent table: the run must end.
    Faulted,
}

impl TableState {
    /// True when the table may be turning because of a demand this driver sent.
    pub fn is_moving(&self) -> bool {
        matches!(
            self,
            TableState::Ramping { .. } | TableState::AtRate { .. } | TableState::Stopping
        )
    }
}

impl fmt::Display for TableState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TableState::Disconnected => write!(f, "disconnected"),
            TableState::Connected => write!(f, "connected (servo not enabled)"),
            TableState::Servoed => write!(f, "servoed"),
            TableState::Ramping { target } => write!(f, "ramping to {target} deg/s"),
            TableState::AtRate { rate } => write!(f, "at rate {rate} deg/s"),
            TableState::Stopping => write!(f, "stopping"),
            TableState::Faulted => write!(f, "faulted"),
        }
    }
}

/// The table controller's mode, as the table reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TableMode {
    /// Zero-rate hold (or servo off when the interlock is open).
    Off,
    /// Rate mode: reaches the demanded rate within the mode's limits.
    Rate,
    /// Position mode.
    Position,
    /// The internal abort profile after a fault or an interlock open.
    Abort,
}

impl fmt::Display for TableMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            TableMode::Off => "OFF",
            TableMode::Rate => "RATE",
            TableMode::Position => "POSITION",
            TableMode::Abort => "ABORT",
        })
    }
}

/// The table's identity, from `*IDN?`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Identity {
    /// Manufacturer (first field).
    pub manufacturer: String,
    /// Controller model (second field).
    pub model: String,
    /// Serial number (third field).
    pub serial: String,
    /// Firmware version (fourth field).
    pub version: String,
}

/// Client-side limits, checked before anything is sent. Set them at or below the table's own
/// limits and the limits of the device under test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Limits {
    /// Largest |rate| that may be demanded, deg/s. Default 30: above the ±20 °/s range of the
    /// HRG in the reference method, with margin for over-range points.
    pub max_rate: f64,
    /// Largest acceleration that may be requested, deg/s². Default 10: a gentle ramp for a
    /// gyro bench (20 °/s in 2 s).
    pub max_acceleration: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_rate: 30.0,
            max_acceleration: 10.0,
        }
    }
}

/// What a table driver can do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capabilities {
    /// The dialect's name, such as `"acl"`.
    pub dialect: &'static str,
    /// Number of axes driven.
    pub axes: u8,
    /// The client-side rate limit in force, deg/s.
    pub max_rate: f64,
    /// The client-side acceleration limit in force, deg/s².
    pub max_acceleration: f64,
    /// Whether the position can be read back.
    pub position_readback: bool,
}

/// The table's mode and status byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableStatus {
    /// The controller's mode.
    pub mode: TableMode,
    /// The IEEE-488.2 status byte (`*STB?`).
    pub status_byte: u8,
}

impl TableStatus {
    /// Bit 0: an interlock event (fault or interlock opened) since the last reset.
    pub fn interlock_event(&self) -> bool {
        self.status_byte & 0x01 != 0
    }
    /// Bit 7: the error queue is not empty.
    pub fn error_queued(&self) -> bool {
        self.status_byte & 0x80 != 0
    }
}

/// How [`RateTable::wait_at_rate`] decides the table is at rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleCriteria {
    /// Absolute tolerance on |measured − demand|, deg/s. Default 0.01.
    pub tolerance: f64,
    /// Added tolerance proportional to |demand| (dimensionless). Default 1e-4 (2 m°/s at 20 °/s).
    pub relative_tolerance: f64,
    /// How long every sample must stay inside the tolerance. Default 2 s.
    pub window: Duration,
    /// Time between samples (each sample is also a heartbeat). Default 100 ms.
    pub interval: Duration,
    /// How long to wait for the window *after* the ramp time has elapsed before declaring a
    /// fault. Default 30 s.
    pub timeout: Duration,
}

impl Default for SettleCriteria {
    fn default() -> Self {
        SettleCriteria {
            tolerance: 0.01,
            relative_tolerance: 1e-4,
            window: Duration::from_secs(2),
            interval: Duration::from_millis(100),
            timeout: Duration::from_secs(30),
        }
    }
}

impl SettleCriteria {
    /// The tolerance in deg/s at a demand.
    pub fn tolerance_at(&self, demand: f64) -> f64 {
        self.tolerance + self.relative_tolerance * demand.abs()
    }
}

/// What [`RateTable::wait_at_rate`] observed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleReport {
    /// The demanded rate, deg/s.
    pub demand: f64,
    /// The minimum ramp time `|Δω|/a` the wait respected.
    pub ramp_time: Duration,
    /// Time from the demand being sent to the end of the stability window.
    pub settled_after: Duration,
    /// When the first sample of the stability window was taken: the table has held the rate
    /// since then (a settling dwell may count from it).
    pub at_rate_since: tokio::time::Instant,
    /// The measured rate over the stability window.
    pub window: RateStats,
}

/// Where a wait for the rate stands, after one sample (see
/// [`RateTable::wait_at_rate_observed`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleProgress {
    /// The demanded rate, deg/s.
    pub demand: f64,
    /// The rate just measured, deg/s.
    pub rate: f64,
    /// The computed ramp is still running.
    pub ramping: bool,
    /// How long the measured rate has stayed within the tolerance (zero when outside it).
    pub stable_for: Duration,
    /// How long it must stay there.
    pub window: Duration,
}

/// What [`RateTable::wait_stopped`] saw when it confirmed the table at rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestReport {
    /// The measured rate that confirmed rest, deg/s (within the driver's stop tolerance).
    pub rate_dps: f64,
    /// The controller's mode at that moment ([`TableMode::Off`]: zero-rate hold, or servo off
    /// after an emergency stop or an interlock opening).
    pub mode: TableMode,
    /// How long the wait took.
    pub waited: Duration,
}

/// Margin added by [`RateTable::stop_deadline`] for reply latency, polling and settling at
/// zero.
pub const STOP_MARGIN: Duration = Duration::from_secs(5);

/// Factor on the deceleration time in [`RateTable::stop_deadline`]: a jerk-limited S-curve
/// stop takes longer than `|rate|/a`.
pub const STOP_TIME_FACTOR: f64 = 1.5;

/// `|rate|/acceleration · STOP_TIME_FACTOR + STOP_MARGIN`, for [`RateTable::stop_deadline`].
/// A rate or acceleration that is not a usable number (NaN, infinite, an acceleration ≤ 0)
/// gives no finite bound: then an hour, long enough that a caller's wait is not cut short by
/// arithmetic, and still a bound.
pub fn stop_time(from_rate: f64, acceleration: f64) -> Duration {
    let secs = from_rate.abs() / acceleration * STOP_TIME_FACTOR;
    match Duration::try_from_secs_f64(secs) {
        Ok(d) if acceleration > 0.0 => d.saturating_add(STOP_MARGIN),
        _ => Duration::from_secs(3600),
    }
}

/// A rate table, whatever its dialect. Methods take `&mut self`: one task owns the driver; other
/// tasks stop the table through a [`StopHandle`].
///
/// Every method that talks to the table can fail with a [`TableError`]; errors whose
/// [`TableError::ends_run`] is true leave the driver [`TableState::Faulted`] after a best-effort
/// controlled stop.
pub trait RateTable: Send {
    /// The link's description, used in every error message.
    fn describe(&self) -> &str;

    /// The driver's current state.
    fn state(&self) -> TableState;

    /// The dialect and the limits in force.
    fn capabilities(&self) -> Capabilities;

    /// Clears stale input, identifies the table, drains stale errors and reads its mode.
    fn connect(&mut self) -> impl Future<Output = Result<Identity, TableError>> + Send;

    /// Resets latched faults, closes the interlock (servo on), sets the rate limit and enters
    /// rate mode. Also the way out of [`TableState::Faulted`]. Refused while moving.
    fn enable(&mut self) -> impl Future<Output = Result<(), TableError>> + Send;

    /// Demands `rate` (deg/s) with acceleration limit `acceleration` (deg/s²). Checks the
    /// client-side limits first, enters rate mode if needed, and reads the error queue.
    fn set_rate(
        &mut self,
        rate: f64,
        acceleration: f64,
    ) -> impl Future<Output = Result<(), TableError>> + Send;

    /// The measured rate, deg/s.
    fn read_rate(&mut self) -> impl Future<Output = Result<f64, TableError>> + Send;

    /// The measured position, degrees in `[0, 360)`.
    fn read_position(&mut self) -> impl Future<Output = Result<f64, TableError>> + Send;

    /// The controller's mode and status byte.
    fn status(&mut self) -> impl Future<Output = Result<TableStatus, TableError>> + Send;

    /// One monitored sample: the measured rate and a status check with the heartbeat deadline.
    /// A latched fault becomes a [`TableErrorKind::Fault`] with the table's text. The rate is
    /// recorded when recording is on. A driver that retries lost replies does so inside the
    /// deadline: a table that went silent fails the sample within it, retries or not.
    fn sample(&mut self) -> impl Future<Output = Result<f64, TableError>> + Send;

    /// Waits until the table is at the demanded rate (see [`SettleCriteria`]); the samples are
    /// recorded when recording is on. A timeout is a [`TableErrorKind::Fault`].
    fn wait_at_rate(
        &mut self,
        criteria: &SettleCriteria,
    ) -> impl Future<Output = Result<SettleReport, TableError>> + Send;

    /// [`RateTable::wait_at_rate`], calling `observe` after every sample (for a progress
    /// display: "waiting for at-rate, 1.2 s stable of 2 s"). The provided method observes
    /// nothing.
    fn wait_at_rate_observed(
        &mut self,
        criteria: &SettleCriteria,
        observe: &mut (dyn FnMut(SettleProgress) + Send),
    ) -> impl Future<Output = Result<SettleReport, TableError>> + Send {
        let _ = observe;
        self.wait_at_rate(criteria)
    }

    /// Starts (or restarts) recording the measured rate of every sample.
    fn start_recording(&mut self);

    /// Stops recording and returns the statistics of the samples since `start_recording`.
    fn stop_recording(&mut self) -> RateStats;

    /// Runs `acquisition` (typically the multimeter's readings, on another port) while sampling
    /// the table every `interval`, and returns its output with the statistics of the measured
    /// rate. A table error ends the wait at once and drops `acquisition`: a faulted table must
    /// stop the step, and the caller then stops the table and clears the multimeter.
    fn record_while<F>(
        &mut self,
        interval: Duration,
        acquisition: F,
    ) -> impl Future<Output = Result<(F::Output, RateStats), TableError>> + Send
    where
        F: Future + Send,
        F::Output: Send,
        Self: Sized,
    {
        async move {
            self.start_recording();
            let mut acquisition = std::pin::pin!(acquisition);
            let mut next = Instant::now();
            loop {
                let (sampled, done) = {
                    let sample = self.sample();
                    let mut sample = std::pin::pin!(sample);
                    tokio::select! {
                        biased;
                        r = &mut sample => (r, None),
                        out = &mut acquisition => (sample.await, Some(out)),
                    }
                };
                if let Err(e) = sampled {
                    self.stop_recording();
                    return Err(e);
                }
                if let Some(out) = done {
                    return Ok((out, self.stop_recording()));
                }
                next = (next + interval).max(Instant::now());
                tokio::select! {
                    out = &mut acquisition => return Ok((out, self.stop_recording())),
                    () = tokio::time::sleep_until(next) => {}
                }
            }
        }
    }

    /// Polls the table's status with the heartbeat deadline. Call it regularly while the table
    /// is otherwise idle; no answer is a [`TableErrorKind::Timeout`] and faults the driver.
    fn heartbeat(&mut self) -> impl Future<Output = Result<(), TableError>> + Send;

    /// Controlled stop (`:Mode:Off 1` in ACL): a smooth deceleration to zero-rate hold. Always
    /// sends, whatever the state (idempotent), and never waits for a reply.
    fn stop(&mut self) -> impl Future<Output = Result<(), TableError>> + Send;

    /// Emergency stop (`:Interlock:Open 1` in ACL): abort profile to zero, then servo off.
    /// Always sends, whatever the state.
    fn emergency_stop(&mut self) -> impl Future<Output = Result<(), TableError>> + Send;

    /// After a stop, waits until the table is at rest and says what it saw. At rest means both
    /// the measured |rate| within the driver's stop tolerance and the controller in
    /// [`TableMode::Off`] (zero-rate hold, or servo off after an emergency stop or an interlock
    /// opening, once the abort profile is done): a rate that merely passes through zero in
    /// RATE mode, or a table held in POSITION mode, is not rest, and neither is an ABORT
    /// profile still running.
    ///
    /// Not at rest within `timeout` is a [`TableErrorKind::Fault`] naming the last measured
    /// rate and mode; so is a table that stops answering while it is waited for (the run must
    /// not assume a table it cannot see has stopped). Bound `timeout` with
    /// [`RateTable::stop_deadline`].
    fn wait_stopped(
        &mut self,
        timeout: Duration,
    ) -> impl Future<Output = Result<RestReport, TableError>> + Send;

    /// How long a stop from `from_rate` (deg/s) may take before its absence is a fault: the
    /// `timeout` to give [`RateTable::wait_stopped`].
    ///
    /// The default is `|from_rate|/max_acceleration · 1.5 + 5 s` ([`stop_time`]) with the
    /// client-side acceleration limit of [`RateTable::capabilities`]: a controlled stop
    /// decelerates at most at the table's acceleration limit, so it takes at least
    /// `|rate|/a`; the factor covers a jerk-limited S-curve, the 5 s reply latency, polling
    /// and settling at zero. A driver that knows a gentler limit is in force (ACL: the last
    /// `:Limit:Acceleration` sent, which `:Mode:Off` also uses) overrides this.
    fn stop_deadline(&self, from_rate: f64) -> Duration {
        stop_time(from_rate, self.capabilities().max_acceleration)
    }

    /// A cloneable handle that can stop the table from another task or a signal handler.
    fn stop_handle(&self) -> StopHandle;

    /// Takes the notes of the queries asked again since the last call (oldest first), one
    /// human sentence each naming the query and what went wrong, such as
    /// "`:Read:Rate? 1`: no reply within 0.667 s; asked again (retry 1 of 2)", so the
    /// sequencer can record them in the run manifest: a run that succeeded on a flaky link
    /// says so. The driver also logs each at `warn` level. The default (a driver that never
    /// retries) has none.
    fn take_retries(&mut self) -> Vec<String> {
        Vec::new()
    }
}
