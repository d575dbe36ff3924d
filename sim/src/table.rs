//! A simulated ACUTROL-style single-axis rate table speaking gyrocal's serial ACL dialect
//! (`shared/docs/rate-table.md`), and, over the same motion model, the experimental Ideal
//! Aerosmith ASCII dialect ([`aerosmith`]).
//!
//! The table runs as a tokio task serving a byte stream (an in-memory pipe or a pseudo-terminal).
//! Its motion is not ticked: the state holds the current profile `Segment` (start time, start
//! rate and position, target, acceleration) and every observation evaluates it in closed form at
//! the observing instant on tokio's clock. Virtual time therefore stays exact and costs nothing
//! while the table "turns" for an hour. Latched faults that depend on the motion (rate trip, a
//! fault injected at a rate) are found analytically too, at the instant they happen.
//!
//! What it models: interlock reset/close/open with an abort profile, latched faults (rate trip,
//! injected fault, a hardware interlock that opens, a table that stops answering), a flaky link
//! (lost, garbled and noise-prefixed replies, see [`ReplyFault`]), RATE and OFF modes with the acceleration and
//! rate limits of RATE mode (an acceleration limit of 0 refuses demands, as on the real table),
//! the error queue and `*STB?`, rate noise on the readback and a once-per-revolution ripple on
//! the actual rate, position integrating the rate and wrapping at 360°.
//!
//! Where it lives: this module holds the configuration, the motion state and the handle a
//! test drives; `acl` serves the ACL dialect over it (command by command), [`aerosmith`] the
//! ASCII dialect, `profile` the closed-form motion segments.

mod acl;
pub mod aerosmith;
mod profile;
#[cfg(test)]
mod tests;

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};

use rand::SeedableRng;
use rand::rngs::StdRng;
use serde::{Deserialize, Serialize};
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt};
use tokio::sync::watch;
use tokio::time::Instant;

use profile::Segment;

/// Longest error queue; further errors replace the last one with `-350,"Queue overflow"`.
const QUEUE_LEN: usize = 16;

/// The error of an interlock that opened by itself (door, hardware interlock): the code and
/// text the manual gives for a demand refused with the interlock open, so one entry means
/// "the interlock is open" whatever opened it.
pub const INTERLOCK_OPEN: (i32, &str) = (201, "Interlock open");

/// Amplitude (deg/s) and period (s) of the wobble of a table told never to settle.
const NEVER_SETTLE_WOBBLE: (f64, f64) = (0.5, 2.0);

/// Faults injected by configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TableFaults {
    /// Latch an injected fault the first time |rate| reaches this value, deg/s (mid-ramp if it
    /// is below the demand). Default none.
    pub inject_at_rate: Option<f64>,
    /// Latch an injected fault this many seconds (sim time) after start. Default none.
    pub inject_after: Option<f64>,
    /// The table's text for an injected fault (error code 220). Default
    /// `"Tracking error limit exceeded"`.
    pub message: String,
    /// Stop answering (and executing) anything this many seconds (sim time) after start.
    /// Default none.
    pub silent_after: Option<f64>,
}

impl Default for TableFaults {
    fn default() -> Self {
        TableFaults {
            inject_at_rate: None,
            inject_after: None,
            message: "Tracking error limit exceeded".into(),
            silent_after: None,
        }
    }
}

/// Configuration of the simulated table. Every field has a default; unknown fields are errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TableConfig {
    /// `*IDN?` reply. Default `"ACUTRONIC,ACUTROL3000,SIM0001,1.0"`.
    pub identity: String,
    /// Largest rate limit the table accepts (`:Limit:Rate`), deg/s. Default 1000.
    pub max_rate: f64,
    /// Largest acceleration limit the table accepts, deg/s²; also the abort deceleration.
    /// Default 100.
    pub max_acceleration: f64,
    /// Rate-trip limit on the actual |rate|, deg/s: above it the table latches a fault.
    /// Default 1100.
    pub trip_rate: f64,
    /// Jerk limit of RATE-mode ramps, deg/s³; none means acceleration steps. Default none.
    pub jerk: Option<f64>,
    /// Standard deviation of the white noise on `:Read:Rate?`, deg/s. Default 0.0005.
    pub rate_noise_std: f64,
    /// Amplitude of the once-per-revolution ripple on the actual rate
    /// (`amplitude·sin(position)`), deg/s. Default 0.0002.
    pub ripple_amplitude: f64,
    /// Sim seconds per real second: 1.0 is real time; above 1 speeds up the dynamics for
    /// real-time tests over pseudo-terminals. Default 1.0.
    pub time_scale: f64,
    /// Never settle: in RATE mode the actual rate wobbles ±0.5 deg/s (2 s period) around the
    /// profile for ever. Default false.
    pub never_settle: bool,
    /// Faults injected by configuration. Default none.
    pub faults: TableFaults,
}

impl Default for TableConfig {
    fn default() -> Self {
        TableConfig {
            identity: "ACUTRONIC,ACUTROL3000,SIM0001,1.0".into(),
            max_rate: 1000.0,
            max_acceleration: 100.0,
            trip_rate: 1100.0,
            jerk: None,
            rate_noise_std: 0.0005,
            ripple_amplitude: 0.0002,
            time_scale: 1.0,
            never_settle: false,
            faults: TableFaults::default(),
        }
    }
}

/// A fault armed for the N-th `:Demand:Rate` the table sees (see [`TableHandle::arm_at_demand`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DemandFault {
    /// A rate trip (error 210) latched halfway through that demand's ramp (at once if the
    /// demand starts no ramp): abort profile, interlock open.
    Trip,
    /// An injected fault (error 220, [`TableFaults::message`]) latched halfway through that
    /// demand's ramp (at once if the demand starts no ramp).
    Fault,
    /// From that demand on (itself included) the table executes and answers nothing: it keeps
    /// doing what it did before.
    Silent,
    /// The interlock opens (a door or a hardware interlock) halfway through that demand's ramp
    /// (at once if the demand starts no ramp): see [`TableHandle::open_interlock`].
    Interlock,
    /// The next `n` query replies after that demand are hit by a [`ReplyFault`] (the demand
    /// itself is executed normally; it has no reply).
    Reply(ReplyFault, u32),
}

/// What happens to one query reply on a flaky link (see [`TableHandle::inject_reply_faults`]).
/// The query is always executed (an error-queue entry read by a lost `:System:Error?` reply is
/// gone); only the bytes on the wire differ.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReplyFault {
    /// No reply line is sent at all.
    Drop,
    /// One character of the reply becomes `#` (the first digit, or the first character of a
    /// reply without digits), so a number, a status byte, a mode or an error entry no longer
    /// parses. An `*IDN?` reply stays four comma-separated fields: no parser can tell.
    Garble,
    /// A noise byte, [`NOISE_BYTE`] (0xFF, what a serial receiver typically delivers for a
    /// glitch on an idle line), is written just before the reply, so the reply line reads with
    /// a junk prefix and is not valid text.
    Noise,
}

/// The byte a [`ReplyFault::Noise`] puts before a reply.
pub const NOISE_BYTE: u8 = 0xFF;

/// Applies `fault` to `reply` (without its terminator); the bytes to write, LF included.
fn faulty_reply(reply: &str, fault: Option<ReplyFault>) -> Vec<u8> {
    faulty_reply_ending(reply, fault, b"\n")
}

/// Applies `fault` to `reply`; the bytes to write, ending with `end` (nothing when dropped).
fn faulty_reply_ending(reply: &str, fault: Option<ReplyFault>, end: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(reply.len() + 2);
    match fault {
        None => bytes.extend_from_slice(reply.as_bytes()),
        Some(ReplyFault::Drop) => return bytes,
        Some(ReplyFault::Garble) => {
            let at = reply.chars().position(|c| c.is_ascii_digit()).unwrap_or(0);
            let garbled: String = reply
                .chars()
                .enumerate()
                .map(|(i, c)| if i == at { '#' } else { c })
                .collect();
            let garbled = if garbled.is_empty() {
                "#".into()
            } else {
                garbled
            };
            bytes.extend_from_slice(garbled.as_bytes());
        }
        Some(ReplyFault::Noise) => {
            bytes.push(NOISE_BYTE);
            bytes.extend_from_slice(reply.as_bytes());
        }
    }
    bytes.extend_from_slice(end);
    bytes
}

/// The table's mode, as `:Mode? 1` reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SimMode {
    /// Zero-rate hold (or servo off with the interlock open).
    Off,
    /// Rate mode.
    Rate,
    /// Abort profile to zero after a fault or `:Interlock:Open`.
    Abort,
}

impl SimMode {
    fn reply(self) -> &'static str {
        match self {
            SimMode::Off => "OFF",
            SimMode::Rate => "RATE",
            SimMode::Abort => "ABORT",
        }
    }
}

struct State {
    config: TableConfig,
    origin: Instant,
    seg: Segment,
    mode: SimMode,
    abort_end: f64,
    interlock_closed: bool,
    fault: Option<String>,
    interlock_event: bool,
    accel_limit: f64,
    rate_limit: f64,
    demand: f64,
    errors: VecDeque<(i32, String)>,
    silent: bool,
    inject_at_rate: Option<f64>,
    inject_after: Option<f64>,
    /// Sim time of an armed rate trip (error 210).
    trip_after: Option<f64>,
    /// Sim time of an armed interlock opening (error 201).
    interlock_after: Option<f64>,
    /// Faults for the next query replies, in order.
    reply_faults: VecDeque<ReplyFault>,
    /// `:Demand:Rate` commands seen (refused ones included).
    demands_seen: u64,
    /// Faults armed for a demand number.
    on_demand: Vec<(u64, DemandFault)>,
    /// Replies held back (the `table:slow` fault).
    slow: Option<Slow>,
    /// Stop commands seen (ACL `:Mode:Off` and `:Interlock:Open`, Aerosmith `STO`).
    stops_seen: u64,
    /// The table goes silent at this stop command (it ignores it and everything after).
    silent_at_stop: Option<u64>,
    rng: StdRng,
}

/// Replies held back by `delay`, for `left` more replies (`None`: from now on).
#[derive(Debug, Clone, Copy)]
struct Slow {
    delay: std::time::Duration,
    left: Option<u32>,
}

impl State {
    /// Counts a stop command; true when the table goes silent at it (it executes nothing).
    pub(crate) fn count_stop(&mut self) -> bool {
        self.stops_seen += 1;
        if self.silent_at_stop == Some(self.stops_seen) {
            tracing::info!("sim table silent from stop {} on", self.stops_seen);
            self.silent = true;
        }
        self.silent
    }

    /// How long the next reply is held back (and one fewer left to hold).
    fn take_reply_delay(&mut self) -> std::time::Duration {
        let Some(slow) = &mut self.slow else {
            return std::time::Duration::ZERO;
        };
        let delay = slow.delay;
        if let Some(left) = &mut slow.left {
            *left = left.saturating_sub(1);
            if *left == 0 {
                self.slow = None;
            }
        }
        delay
    }
}

/// Writes replies in order, each not before its release instant: a table whose replies come
/// late (a controller busy with a profile, a serial converter with a deep buffer, a network
/// bridge) still answers in order. Without a delay a reply is written at once.
pub(crate) fn spawn_reply_writer<W>(
    mut write: W,
) -> tokio::sync::mpsc::UnboundedSender<(Instant, Vec<u8>)>
where
    W: AsyncWrite + Send + Unpin + 'static,
{
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<(Instant, Vec<u8>)>();
    tokio::spawn(async move {
        while let Some((at, bytes)) = rx.recv().await {
            tokio::time::sleep_until(at).await;
            if write.write_all(&bytes).await.is_err() || write.flush().await.is_err() {
                return;
            }
        }
    });
    tx
}

impl State {
    fn sim_time(&self, at: Instant) -> f64 {
        at.saturating_duration_since(self.origin).as_secs_f64() * self.config.time_scale
    }

    fn push_error(&mut self, code: i32, text: impl Into<String>) {
        let text = text.into();
        tracing::debug!("sim table error {code},\"{text}\"");
        if self.errors.len() >= QUEUE_LEN {
            self.errors.pop_back();
            self.errors.push_back((-350, "Queue overflow".into()));
        } else {
            self.errors.push_back((code, text));
        }
    }

    fn servo_on(&self) -> bool {
        self.interlock_closed || self.mode == SimMode::Abort
    }

    /// Actual rate at sim time `t` (profile + ripple + wobble); valid after `advance(t)`.
    fn actual(&self, t: f64) -> f64 {
        let base = self.seg.rate(t);
        if !self.servo_on() && base == 0.0 {
            return 0.0;
        }
        let ripple = self.config.ripple_amplitude * self.seg.position(t).to_radians().sin();
        let wobble = if self.config.never_settle && self.mode == SimMode::Rate {
            let (amp, period) = NEVER_SETTLE_WOBBLE;
            amp * (std::f64::consts::TAU * t / period).sin()
        } else {
            0.0
        };
        base + ripple + wobble
    }

    /// Starts a new profile segment at `t` towards `target`.
    fn ramp_to(&mut self, t: f64, target: f64, accel: f64, jerk: Option<f64>) {
        self.seg = Segment {
            t0: t,
            p0: self.seg.position(t),
            w0: self.seg.rate(t),
            target,
            accel,
            jerk,
        };
    }

    fn latch(&mut self, t: f64, code: i32, text: String) {
        if self.fault.is_some() {
            return;
        }
        tracing::info!("sim table latched fault at t={t:.3}: {text}");
        self.push_error(code, text.clone());
        self.fault = Some(text);
        self.interlock_event = true;
        self.abort(t);
    }

    fn abort(&mut self, t: f64) {
        if self.servo_on() {
            self.ramp_to(t, 0.0, self.config.max_acceleration, None);
            self.mode = SimMode::Abort;
            self.abort_end = self.seg.end();
        }
        self.interlock_closed = false;
        self.demand = 0.0;
    }

    /// Brings latched events up to sim time `t`, in order.
    fn advance(&mut self, t: f64) {
        for _ in 0..8 {
            if self.mode == SimMode::Abort && t >= self.abort_end {
                let end = self.abort_end;
                self.seg = Segment::hold(end, self.seg.position(end), 0.0);
                self.mode = SimMode::Off;
            }
            if let Some(s) = self.config.faults.silent_after
                && t >= s
            {
                self.silent = true;
            }
            if !self.interlock_closed {
                return;
            }
            let mut first: Option<(f64, i32, String)> = None;
            let mut consider = |when: Option<f64>, code: i32, text: &dyn Fn(f64) -> String| {
                if let Some(w) = when
                    && w <= t
                    && first.as_ref().is_none_or(|f| w < f.0)
                {
                    first = Some((w, code, text(w)));
                }
            };
            let seg = self.seg;
            let message = self.config.faults.message.clone();
            consider(self.inject_after.map(|a| a.max(seg.t0)), 220, &|_| {
                message.clone()
            });
            consider(
                self.inject_at_rate.and_then(|r| seg.first_crossing(r)),
                220,
                &|_| message.clone(),
            );
            let armed_interlock = self.interlock_after.map(|a| a.max(seg.t0));
            consider(armed_interlock, INTERLOCK_OPEN.0, &|_| {
                INTERLOCK_OPEN.1.into()
            });
            let armed_trip = self.trip_after.map(|a| a.max(seg.t0));
            consider(armed_trip, 210, &|w| {
                format!("Rate trip: {:.3} deg/s (armed trip)", seg.rate(w).abs())
            });
            let trip = self.config.trip_rate;
            consider(seg.first_crossing(trip), 210, &|w| {
                format!(
                    "Rate trip: {:.3} deg/s above the trip limit {trip} deg/s",
                    seg.rate(w).abs()
                )
            });
            let Some((when, code, text)) = first else {
                let now_rate = self.actual(t).abs();
                if now_rate > trip {
                    self.latch(
                        t,
                        210,
                        format!("Rate trip: {now_rate:.3} deg/s above the trip limit {trip} deg/s"),
                    );
                    continue;
                }
                return;
            };
            if code == 220 {
                self.inject_after = None;
                self.inject_at_rate = None;
            }
            if code == 210 && armed_trip == Some(when) {
                self.trip_after = None;
            }
            if code == INTERLOCK_OPEN.0 {
                self.interlock_after = None;
            }
            self.latch(when, code, text);
        }
    }

    /// A controlled stop at `t` (ACL `:Mode:Off`, Aerosmith `STO`): with the servo on, a ramp
    /// to zero at the acceleration limit in force (the table's maximum if none was set).
    fn controlled_stop(&mut self, t: f64) {
        if self.interlock_closed {
            let accel = if self.accel_limit > 0.0 {
                self.accel_limit
            } else {
                self.config.max_acceleration
            };
            let jerk = self.config.jerk;
            self.ramp_to(t, 0.0, accel, jerk);
            self.mode = SimMode::Off;
            self.demand = 0.0;
        }
    }

    /// Counts a rate demand (ACL `:Demand:Rate`, Aerosmith `JOG`) and takes the faults armed
    /// for it; `None` when the table goes silent at this demand (it executes nothing).
    fn count_demand(&mut self) -> Option<Vec<DemandFault>> {
        self.demands_seen += 1;
        let n = self.demands_seen;
        let mut armed = Vec::new();
        self.on_demand.retain(|&(k, f)| {
            if k == n {
                armed.push(f);
                false
            } else {
                true
            }
        });
        if armed.contains(&DemandFault::Silent) {
            tracing::info!("sim table silent from demand {n} on");
            self.silent = true;
            return None;
        }
        Some(armed)
    }

    /// Arms the faults taken by [`State::count_demand`] once the demand was executed at `t`.
    fn arm_demand_faults(&mut self, t: f64, armed: Vec<DemandFault>) {
        let n = self.demands_seen;
        // halfway through the ramp this demand started, or now if it started none
        let mid = if self.seg.t0 == t {
            t + self.seg.duration() / 2.0
        } else {
            t
        };
        for f in armed {
            tracing::info!("sim table: {f:?} armed at demand {n} for t={mid:.3}");
            match f {
                DemandFault::Trip => self.trip_after = Some(mid),
                DemandFault::Fault => self.inject_after = Some(mid),
                DemandFault::Interlock => self.interlock_after = Some(mid),
                DemandFault::Reply(fault, count) => {
                    for _ in 0..count {
                        self.reply_faults.push_back(fault);
                    }
                }
                DemandFault::Silent => {}
            }
        }
        self.advance(t);
    }

    fn status_byte(&self) -> u8 {
        u8::from(self.interlock_event) | if self.errors.is_empty() { 0 } else { 0x80 }
    }
}

/// A running simulated table. See [`SimTable::spawn`].
#[derive(Debug)]
pub struct SimTable;

impl SimTable {
    /// A table with no link yet (its clock starts now): serve links with
    /// [`TableHandle::serve_link`], one or several, one after the other or at once (a
    /// pseudo-terminal and a TCP port, a client that reconnects).
    pub fn idle(config: TableConfig, seed: u64) -> TableHandle {
        TableHandle::new(config, seed)
    }

    /// Serves the ACL dialect on `stream` as a tokio task (on tokio's clock: fine in paused
    /// virtual time) until the stream closes or [`TableHandle::shutdown`]. `seed` seeds the
    /// readback noise.
    pub fn spawn<S>(stream: S, config: TableConfig, seed: u64) -> TableHandle
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let handle = TableHandle::new(config, seed);
        let task = handle.clone();
        tokio::spawn(async move { task.serve(stream).await });
        handle
    }
}

/// A cloneable view of a simulated table: the truth (actual rate, mode, demand), fault
/// injection and shutdown. `Send + Sync`; every call evaluates the table at the current instant.
#[derive(Clone)]
pub struct TableHandle {
    state: Arc<Mutex<State>>,
    shutdown: Arc<watch::Sender<bool>>,
}

impl std::fmt::Debug for TableHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TableHandle")
            .field("mode", &self.mode())
            .field("demanded_rate", &self.demanded_rate())
            .finish_non_exhaustive()
    }
}

impl TableHandle {
    fn new(config: TableConfig, seed: u64) -> Self {
        let faults = config.faults.clone();
        let rate_limit = config.max_rate;
        TableHandle {
            state: Arc::new(Mutex::new(State {
                config,
                origin: Instant::now(),
                seg: Segment::hold(0.0, 0.0, 0.0),
                mode: SimMode::Off,
                abort_end: 0.0,
                interlock_closed: false,
                fault: None,
                interlock_event: false,
                accel_limit: 0.0,
                rate_limit,
                demand: 0.0,
                errors: VecDeque::new(),
                silent: false,
                inject_at_rate: faults.inject_at_rate,
                inject_after: faults.inject_after,
                trip_after: None,
                interlock_after: None,
                reply_faults: VecDeque::new(),
                demands_seen: 0,
                on_demand: Vec::new(),
                slow: None,
                stops_seen: 0,
                silent_at_stop: None,
                rng: StdRng::seed_from_u64(seed),
            })),
            shutdown: Arc::new(watch::channel(false).0),
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Locks the state brought up to `at`; returns it with the sim time of `at`.
    ///
    /// Latched events are brought up to `min(at, now)` only: evaluating a future instant (a
    /// multimeter asking for a window that has not ended) must not latch a fault early.
    fn at(&self, at: Instant) -> (MutexGuard<'_, State>, f64) {
        let mut st = self.lock();
        let t = st.sim_time(at);
        let now = st.sim_time(Instant::now());
        st.advance(t.min(now));
        (st, t)
    }

    /// Sim seconds elapsed at `at` since the table started (scaled by `time_scale`).
    pub fn sim_time(&self, at: Instant) -> f64 {
        self.lock().sim_time(at)
    }

    /// The configuration.
    pub fn config(&self) -> TableConfig {
        self.lock().config.clone()
    }

    /// The actual rate at `at` (what a gyro on the table senses), deg/s: the profile plus the
    /// once-per-revolution ripple (and the wobble of a never-settling table), without readback
    /// noise. Instants before "now" are fine as long as no command changed the profile since.
    pub fn actual_rate(&self, at: Instant) -> f64 {
        let (st, t) = self.at(at);
        st.actual(t)
    }

    /// The position at `at`, degrees in `[0, 360)`.
    pub fn position(&self, at: Instant) -> f64 {
        let (st, t) = self.at(at);
        st.seg.position(t).rem_euclid(360.0)
    }

    /// The mode now.
    pub fn mode(&self) -> SimMode {
        self.at(Instant::now()).0.mode
    }

    /// The demanded rate now, deg/s (0 unless in RATE mode with a demand).
    pub fn demanded_rate(&self) -> f64 {
        let (st, _) = self.at(Instant::now());
        if st.mode == SimMode::Rate {
            st.demand
        } else {
            0.0
        }
    }

    /// True when the table is not commanded to turn and its profile has reached zero: what
    /// a program must leave behind.
    pub fn is_stopped(&self) -> bool {
        let (st, t) = self.at(Instant::now());
        st.mode != SimMode::Abort && st.demand == 0.0 && st.seg.rate(t) == 0.0
    }

    /// Whether the interlock is closed (servo on).
    pub fn interlock_closed(&self) -> bool {
        self.at(Instant::now()).0.interlock_closed
    }

    /// The latched fault's text, if any.
    pub fn fault(&self) -> Option<String> {
        self.at(Instant::now()).0.fault.clone()
    }

    /// Latches an injected fault now (error 220 with `message`): abort profile, interlock open.
    pub fn inject_fault(&self, message: &str) {
        let (mut st, t) = self.at(Instant::now());
        st.latch(t, 220, message.to_string());
    }

    /// Latches a rate trip now (error 210), whatever the rate.
    pub fn trip(&self) {
        let (mut st, t) = self.at(Instant::now());
        let rate = st.actual(t).abs();
        st.latch(t, 210, format!("Rate trip: {rate:.3} deg/s (forced)"));
    }

    /// Opens the interlock now, as a door switch or a hardware interlock does: the axis aborts
    /// (abort profile to zero at the table's maximum acceleration, mode ABORT, then servo off
    /// and mode OFF), the interlock-event bit (bit 0 of `*STB?`) is set, error
    /// [`INTERLOCK_OPEN`] (`201,"Interlock open"`) is queued, and the event latches: the axis
    /// needs `:Interlock:Reset` before `:Interlock:Close`. Nothing happens if the interlock is
    /// already open (no servo to stop).
    pub fn open_interlock(&self) {
        let (mut st, t) = self.at(Instant::now());
        if st.interlock_closed {
            let (code, text) = INTERLOCK_OPEN;
            st.latch(t, code, text.into());
        }
    }

    /// The next `count` query replies are hit by `fault` (after any already pending).
    pub fn inject_reply_faults(&self, fault: ReplyFault, count: u32) {
        let mut st = self.lock();
        for _ in 0..count {
            st.reply_faults.push_back(fault);
        }
    }

    /// Reply faults injected and not yet applied.
    pub fn pending_reply_faults(&self) -> usize {
        self.lock().reply_faults.len()
    }

    /// Arms an injected fault at |rate| ≥ `rate` (latched at the exact instant, mid-ramp).
    pub fn inject_fault_at_rate(&self, rate: f64) {
        self.at(Instant::now()).0.inject_at_rate = Some(rate);
    }

    /// Holds the next `count` replies (every reply from now on with `None`) back by `delay`:
    /// commands are executed when they arrive, their replies come late and in order (the
    /// `table:slow` fault). A zero delay ends it.
    pub fn hold_replies(&self, delay: std::time::Duration, count: Option<u32>) {
        let mut st = self.lock();
        st.slow = (!delay.is_zero() && count != Some(0)).then_some(Slow { delay, left: count });
    }

    /// Makes the table go silent at the `n`-th stop command it sees (counted from 1 since the
    /// start): it ignores that stop and everything after it, and keeps turning as it was (a
    /// controller that hangs when asked to stop; the `table:silent@stopN` fault).
    pub fn arm_silent_at_stop(&self, n: u64) {
        self.lock().silent_at_stop = Some(n);
    }

    /// Stop commands seen so far.
    pub fn stops_seen(&self) -> u64 {
        self.lock().stops_seen
    }

    /// The real (tokio) duration of `sim_s` sim seconds on this table's clock.
    pub fn sim_duration(&self, sim_s: f64) -> std::time::Duration {
        let scale = self.lock().config.time_scale;
        let scale = if scale.is_finite() && scale > 0.0 {
            scale
        } else {
            1.0
        };
        std::time::Duration::try_from_secs_f64(sim_s.max(0.0) / scale).unwrap_or_default()
    }

    /// Whether replies are being held back.
    pub fn is_slow(&self) -> bool {
        self.lock().slow.is_some()
    }

    /// Stops (true) or resumes (false) answering and executing anything.
    pub fn set_silent(&self, silent: bool) {
        let mut st = self.lock();
        st.silent = silent;
        if !silent {
            st.config.faults.silent_after = None;
        }
    }

    /// Arms `fault` for the `n`-th `:Demand:Rate` the table sees (counted from 1 since the
    /// start, refused demands included; see [`DemandFault`] for what happens). A number already
    /// passed never fires.
    pub fn arm_at_demand(&self, n: u64, fault: DemandFault) {
        self.lock().on_demand.push((n, fault));
    }

    /// `:Demand:Rate` commands seen so far (refused ones included).
    pub fn demands_seen(&self) -> u64 {
        self.lock().demands_seen
    }

    /// Whether the table is silent (answers and executes nothing).
    pub fn is_silent(&self) -> bool {
        self.at(Instant::now()).0.silent
    }

    /// Serves the ACL dialect on one more `stream` against this same table, as a tokio task,
    /// until that stream closes or [`TableHandle::shutdown`]. Returns the task.
    pub fn serve_link<S>(&self, stream: S) -> tokio::task::JoinHandle<()>
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let task = self.clone();
        tokio::spawn(async move { task.serve(stream).await })
    }

    /// Ends the simulator task; the stream is closed.
    pub fn shutdown(&self) {
        self.shutdown.send_replace(true);
    }
}
