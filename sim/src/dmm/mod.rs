//! A simulated HP 34401A on its RS-232 port (or on GPIB behind a controller: see GPIB mode below).
//!
//! [`SimDmm::spawn`] serves the meter's wire protocol on any async byte stream (one end of an
//! in-memory pipe in virtual time, or the master side of a pseudo-terminal in real time) as a
//! tokio task. It follows `shared/docs/hp34401a.md`:
//!
//! - `SYST:REM` must come first (strict by default): before it, the meter is in LOCAL and what
//!   it does with the other commands is [`DmmConfig::local_mode`] (default: every other command
//!   is refused with error 550 "Command not allowed in local" and queries are not answered);
//! - long and short forms, case-insensitive; `;` chains within a subsystem, `;:` returns to the
//!   root; several queries on one line answer `;`-separated on one line; every reply ends CR LF;
//! - the five NPLC values (anything else -222 "Data out of range"); `INIT` stores at most 512
//!   readings (more: error 531 "Insufficient memory") and the meter is deaf until the burst ends;
//!   `READ?` streams readings to the output as they are taken (measuring pauses while the output
//!   buffer is full); `FETC?` sends the stored readings; readings are `SD.DDDDDDDDESDD`,
//!   overloads `+9.90000000E+37`;
//! - a 20-entry error queue (-350 "Queue overflow" replaces the last entry when it is full) with
//!   the standard codes; queries that pile up raise -410 "Query INTERRUPTED" (a reply had begun)
//!   or -420 "Query UNTERMINATED" (no reply had begun), and the earlier replies are lost;
//! - Ctrl-C (0x03) is the device clear: aborts the measurement, empties the input and output
//!   buffers, keeps the configuration and the error queue;
//! - a power cycle ([`Fault::PowerCycle`], `dmm:powercycle@...`): the meter is dead for the off
//!   time ([`DmmConfig::power_off_s`], default 5 s; everything received is lost, nothing is
//!   sent, a measurement in progress is lost) and comes back as after power-on: in LOCAL, with
//!   the `*RST` settings (NPLC 10, autozero on, autorange...), empty reading memory, empty input
//!   and output buffers, empty error queue, and the Power On bit (128) set in the Standard Event
//!   register (`*ESR?` reads and clears it, as does `*CLS`; the other event bits are not
//!   modelled);
//! - `FETC?` with an empty reading memory (after power-on, `*RST`, or before any `INIT`) sends
//!   no reply and queues -230 "Data stale" (the SCPI "data corrupt or stale" error that sibling
//!   HP instruments' manuals give for `FETC?` in the idle state or after `*RST`, with no result
//!   returned; unconfirmed for the 34401A itself);
//! - timing from the doc's model on tokio's clock (so it runs in virtual time): the command's
//!   characters on the wire, 20 ms to arm, per reading `delay + NPLC/f_line` (twice the
//!   integration with autozero on), and output at 11 bits per character at the configured baud.
//!
//! GPIB mode ([`DmmConfig::interface`] = `gpib`, a small option for the simulated Prologix
//! controller in [`crate::prologix`]): the stream then stands for the GPIB bus behind a
//! controller. The meter is in remote from the start (the controller holds REN), so it needs no
//! `SYST:REM`; `SYST:REM`, `SYST:RWL` and `SYST:LOC` are RS-232-only commands in the manual, and
//! the simulator refuses them over GPIB with -113 "Undefined header" (its choice, unconfirmed
//! on a real meter: it makes a driver that sends them fail its tests). Replies end in LF (with
//! EOI on the real bus); the meter sends only while addressed to talk, and stops talking after
//! the LF that ends a message, so a reply waits in its output buffer until the controller reads
//! it. Bus events travel in band as single bytes the controller writes: [`GPIB_SDC`] (0x03,
//! the same byte as the RS-232 device clear) is Selected Device Clear, [`GPIB_TALK`] addresses
//! the meter to talk, [`GPIB_UNTALK`] unaddresses it. Addressed to talk with nothing to say and
//! no query pending, the meter queues -420 "Query UNTERMINATED" (what `++auto 1` provokes after
//! a command; when commands received before the talk address have not run yet, the check waits
//! for them, as on a meter that runs a command as soon as its terminator arrives, so `*CLS`
//! then `++read` still leaves the -420). Bytes cross the bus at [`GPIB_CHAR_TIME`] each.
//!
//! The input voltage comes from a [`SignalSource`] sampled over each reading's integration
//! window, plus seeded gaussian noise. Faults can be scheduled in [`DmmConfig::faults`] or
//! injected at run time through [`DmmHandle::inject`].
//!
//! Where it lives: this module holds the meter's state, its wire (RS-232 or GPIB), timing and
//! output; `config` its configuration, `parse` the SCPI program-message parser, `commands`
//! what each command does, `faults` injected faults and the power cycle. What it shares with
//! the simulated Truevolt (the error queue, the fault grammar and handle, reply faults,
//! reading format) is in [`crate::scpi`].

mod commands;
mod config;
mod faults;
mod parse;

use config::sanitize;
pub use config::{DmmConfig, Interface, LocalMode, ScheduledFault};

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::SignalSource;
use crate::scpi::{
    ArmedFaults, Ctl, ErrorQueue, EventStatus, Noise, ReplyFault, SlowReplies, clip,
};
pub use gyrocal_link::Framing;
use parse::{Cmd, Unit, parse_line};

/// The fault grammar, the handle and the counters are every simulated meter's
/// ([`crate::scpi`]); they keep their names here.
pub use crate::scpi::{
    DmmHandle, DmmInjector, DmmStats, ERROR_QUEUE_SIZE, Fault, OVERLOAD, format_reading,
};

/// What a real unit answers to `*IDN?` (firmware 11-5-2; 7-5-2 and 10-5-2 exist too).
pub const DEFAULT_IDENTITY: &str = "HEWLETT-PACKARD,34401A,0,11-5-2";
/// Readings the internal memory holds.
pub const MEMORY_SIZE: usize = 512;
/// Time to enter wait-for-trigger (`INIT`, `READ?`), before scaling.
pub const ARM_TIME: Duration = Duration::from_millis(20);
/// GPIB mode: the in-band byte for Selected Device Clear (the RS-232 device clear byte).
pub const GPIB_SDC: u8 = gyrocal_link::DEVICE_CLEAR;
/// GPIB mode: the in-band byte that addresses the meter to talk (MTA on a real bus).
pub const GPIB_TALK: u8 = 0x05;
/// GPIB mode: the in-band byte that unaddresses the meter (UNT on a real bus).
pub const GPIB_UNTALK: u8 = 0x06;
/// GPIB mode: time per byte on the bus, before scaling: the driver's figure (about 100 kB/s
/// through a Prologix controller, an assumption), so the driver's timing model and the
/// simulated bus agree.
pub const GPIB_CHAR_TIME: Duration = gyrocal_hp34401a::timing::GPIB_CHAR_TIME;

/// The simulated 34401A.
pub struct SimDmm;

impl SimDmm {
    /// Serves the meter on `stream` as a tokio task. `source` gives the input voltage; `seed`
    /// seeds the reading noise. An invalid `config` is logged and its bad values replaced by
    /// the defaults.
    pub fn spawn<S>(
        stream: S,
        config: DmmConfig,
        source: Box<dyn SignalSource>,
        seed: u64,
    ) -> DmmHandle
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let config = sanitize(config);
        let (tx, rx) = mpsc::unbounded_channel();
        let stats = Arc::new(Mutex::new(DmmStats::default()));
        let meter = Meter::new(config, source, seed, stats.clone());
        let task = tokio::spawn(meter.run(stream, rx));
        DmmHandle::from_parts(tx, stats, task)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Zero {
    On,
    Off,
    Once,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TrigSource {
    Imm,
    Bus,
    Ext,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Dest {
    Memory,
    Output,
}

/// The settings `*RST` restores.
#[derive(Debug, Clone, PartialEq)]
struct Settings {
    range: Option<f64>,
    nplc: f64,
    zero: Zero,
    imp_auto: bool,
    trig_source: TrigSource,
    trig_delay: Option<f64>,
    trig_count: u32,
    samp_count: u32,
    display: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            range: None,
            nplc: 10.0,
            zero: Zero::On,
            imp_auto: false,
            trig_source: TrigSource::Imm,
            trig_delay: None,
            trig_count: 1,
            samp_count: 1,
            display: true,
        }
    }
}

struct Line {
    text: String,
    ready_at: Instant,
}

/// The line being executed.
struct Exec {
    units: VecDeque<Unit>,
    has_output: bool,
    fault: Option<ReplyFault>,
    muted: bool,
}

/// A measurement in progress.
struct Meas {
    dest: Dest,
    /// Readings left in this trigger's set.
    left_in_set: u32,
    /// Triggers left after this one.
    triggers_left: u32,
    /// Waiting for a trigger (BUS or EXT source).
    awaiting_trigger: bool,
    /// The current reading: start of its integration window and when it completes.
    window_start: Instant,
    done_at: Instant,
    /// Paused: the output buffer cannot take another reading.
    blocked: bool,
    /// Readings this measurement has produced.
    produced: u64,
}

struct Meter {
    cfg: DmmConfig,
    source: Box<dyn SignalSource>,
    noise: Noise,
    stats: Arc<Mutex<DmmStats>>,
    counters: DmmStats,
    remote: bool,
    set: Settings,
    errors: ErrorQueue,
    memory: Vec<f64>,
    inbuf: Vec<u8>,
    lines: VecDeque<Line>,
    in_wire_free: Instant,
    exec: Option<Exec>,
    meas: Option<Meas>,
    out: VecDeque<u8>,
    tx: Option<(Vec<u8>, Instant)>,
    out_wire_free: Instant,
    /// When the bytes now first in `out` were queued.
    out_time: Instant,
    /// The exact time of the event being processed (tokio's timer wakes on whole
    /// milliseconds; the model's times are kept exact so they do not drift).
    clock: Instant,
    pending_reply_fault: VecDeque<ReplyFault>,
    overloads_left: u32,
    disconnect: bool,
    stop: bool,
    faults: Vec<ScheduledFault>,
    /// Faults armed for a reading number (see [`DmmHandle::inject_at_reading`]).
    at_reading: ArmedFaults,
    /// A reply fault for the reading at this index of the memory, applied by `FETC?`.
    memory_fault: Option<(usize, ReplyFault)>,
    /// Standard Event register (only the Power On bit is modelled).
    esr: EventStatus,
    /// Switched off until then (a power cycle).
    off_until: Option<Instant>,
    /// A [`Fault::Slow`] in force: the delay, and the replies it still holds back (`None`:
    /// every one).
    slow: SlowReplies,
    /// Bytes on their way to the host, with the instant they arrive (in order).
    delayed: VecDeque<(Vec<u8>, Instant)>,
    /// GPIB mode: addressed to talk.
    talk: bool,
    /// GPIB mode: addressed to talk while commands were still waiting to run; whether that
    /// is a -420 is decided once they have run.
    talk_check: bool,
}

fn scaled(cfg: &DmmConfig, d: Duration) -> Duration {
    d.div_f64(cfg.time_scale)
}

impl Meter {
    fn new(
        cfg: DmmConfig,
        source: Box<dyn SignalSource>,
        seed: u64,
        stats: Arc<Mutex<DmmStats>>,
    ) -> Self {
        let noise = Noise::new(cfg.noise_v, seed);
        let now = Instant::now();
        let mut faults = cfg.faults.clone();
        faults.sort_by_key(|f| std::cmp::Reverse(f.after_commands));
        Meter {
            remote: !cfg.strict_remote || cfg.interface == Interface::Gpib,
            talk: false,
            talk_check: false,
            cfg,
            source,
            noise,
            stats,
            counters: DmmStats::default(),
            set: Settings::default(),
            errors: ErrorQueue::default(),
            memory: Vec::new(),
            inbuf: Vec::new(),
            lines: VecDeque::new(),
            in_wire_free: now,
            exec: None,
            meas: None,
            out: VecDeque::new(),
            tx: None,
            out_wire_free: now,
            out_time: now,
            clock: now,
            pending_reply_fault: VecDeque::new(),
            overloads_left: 0,
            disconnect: false,
            stop: false,
            faults,
            at_reading: ArmedFaults::default(),
            memory_fault: None,
            esr: EventStatus::powered_on(),
            off_until: None,
            slow: SlowReplies::default(),
            delayed: VecDeque::new(),
        }
    }

    async fn run<S>(mut self, stream: S, mut ctl: mpsc::UnboundedReceiver<Ctl>)
    where
        S: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let (mut rd, mut wr) = tokio::io::split(stream);
        let mut buf = [0u8; 1024];
        let mut ctl_open = true;
        loop {
            let now = Instant::now();
            self.advance(now);
            if self.may_send()
                && let Some((bytes, due)) = self.tx.take_if(|(_, due)| *due <= now)
            {
                let _ = due;
                if self.slow.is_active() || !self.delayed.is_empty() {
                    // held back (or behind bytes that are): they arrive later, in order
                    if self.gpib() && bytes.last() == Some(&b'\n') {
                        self.talk = false;
                    }
                    self.hold_back(bytes, now);
                    continue;
                }
                if wr.write_all(&bytes).await.is_err() || wr.flush().await.is_err() {
                    break;
                }
                if self.gpib() && bytes.last() == Some(&b'\n') {
                    // end of message (EOI): the meter stops talking
                    self.talk = false;
                }
                continue;
            }
            if self.delayed.front().is_some_and(|(_, at)| *at <= now)
                && let Some((bytes, _)) = self.delayed.pop_front()
            {
                if wr.write_all(&bytes).await.is_err() || wr.flush().await.is_err() {
                    break;
                }
                continue;
            }
            self.publish();
            if self.stop || self.disconnect {
                break;
            }
            let wake = self.next_wake();
            tokio::select! {
                biased;
                c = ctl.recv(), if ctl_open => match c {
                    Some(Ctl::Fault(f)) => self.inject(f),
                    Some(Ctl::AtReading(n, f)) => self.at_reading.arm(n, f),
                    Some(Ctl::Stop) => self.stop = true,
                    None => ctl_open = false,
                },
                r = rd.read(&mut buf) => match r {
                    Ok(0) | Err(_) => break,
                    Ok(n) => self.input(&buf[..n]),
                },
                () = sleep_until_opt(wake) => {}
            }
        }
        let _ = wr.shutdown().await;
        self.counters.stopped = true;
        self.publish();
        tracing::debug!("simulated 34401A stopped");
    }

    fn publish(&mut self) {
        self.counters.remote = self.remote;
        self.counters.powered = self.off_until.is_none();
        self.counters.nplc = self.set.nplc;
        self.counters.memory_points = self.memory.len();
        self.counters.error_queue = self.errors.snapshot();
        if let Ok(mut s) = self.stats.lock() {
            *s = self.counters.clone();
        }
    }

    fn gpib(&self) -> bool {
        self.cfg.interface == Interface::Gpib
    }

    /// Whether output may go out now: always on RS-232, while addressed to talk on GPIB.
    fn may_send(&self) -> bool {
        !self.gpib() || self.talk
    }

    fn char_time(&self) -> Duration {
        if self.gpib() {
            return scaled(&self.cfg, GPIB_CHAR_TIME);
        }
        scaled(
            &self.cfg,
            Duration::from_secs_f64(11.0 / f64::from(self.cfg.baud)),
        )
    }

    /// Puts bytes the meter sent at `now` on their way with the [`Fault::Slow`] delay in
    /// force (none when it ran out: they still wait behind the earlier ones).
    fn hold_back(&mut self, bytes: Vec<u8>, now: Instant) {
        let lines = bytes.iter().filter(|&&b| b == b'\n').count() as u64;
        let delay = match self.slow.hold(lines) {
            Some(delay) => {
                self.counters.late_replies += lines;
                delay
            }
            None => Duration::ZERO,
        };
        let at = self
            .delayed
            .back()
            .map_or(now + delay, |(_, last)| (*last).max(now + delay));
        self.delayed.push_back((bytes, at));
    }

    fn next_wake(&self) -> Option<Instant> {
        let in_transit = self.delayed.front().map(|(_, at)| *at);
        if let Some(off) = self.off_until {
            return Some(in_transit.map_or(off, |t| t.min(off)));
        }
        let mut wake: Option<Instant> = in_transit;
        let mut consider = |t: Instant| wake = Some(wake.map_or(t, |w| w.min(t)));
        if let Some((_, due)) = &self.tx
            && self.may_send()
        {
            consider(*due);
        }
        if let Some(m) = &self.meas
            && !m.blocked
            && !m.awaiting_trigger
        {
            consider(m.done_at);
        }
        if self.meas.is_none()
            && self.exec.is_none()
            && let Some(l) = self.lines.front()
        {
            consider(l.ready_at);
        }
        wake
    }

    // ---- input -------------------------------------------------------------------------

    fn input(&mut self, bytes: &[u8]) {
        if self.off_until.is_some() {
            // switched off: whatever arrives is lost
            return;
        }
        let now = Instant::now();
        for &b in bytes {
            match b {
                gyrocal_link::DEVICE_CLEAR => self.device_clear(),
                GPIB_TALK if self.gpib() => self.talk_addressed(),
                GPIB_UNTALK if self.gpib() => self.talk = false,
                b'\n' => {
                    let mut raw = std::mem::take(&mut self.inbuf);
                    if raw.last() == Some(&b'\r') {
                        raw.pop();
                    }
                    self.line_arrived(String::from_utf8_lossy(&raw).into_owned(), now);
                }
                _ => {
                    if self.inbuf.len() < 4096 {
                        self.inbuf.push(b);
                    }
                }
            }
        }
        let backlog = self.inbuf.len() + self.lines.iter().map(|l| l.text.len() + 1).sum::<usize>();
        self.counters.max_input_backlog = self.counters.max_input_backlog.max(backlog);
    }

    /// GPIB mode: addressed to talk. With nothing to say and no query pending, -420.
    fn talk_addressed(&mut self) {
        self.talk = true;
        if self.query_pending() || self.meas.is_some() {
            return;
        }
        if self.lines.is_empty() && self.exec.is_none() {
            self.raise(-420, "Query UNTERMINATED");
        } else {
            // commands still to run (a real meter would have run them already): decide after
            self.talk_check = true;
        }
    }

    /// The deferred -420 check of [`Meter::talk_addressed`], once the commands have run.
    fn deferred_talk_check(&mut self) {
        if self.talk_check && self.lines.is_empty() && self.exec.is_none() && self.meas.is_none() {
            self.talk_check = false;
            if self.talk && !self.query_pending() {
                self.raise(-420, "Query UNTERMINATED");
            }
        }
    }

    fn device_clear(&mut self) {
        self.counters.device_clears += 1;
        self.talk = false;
        self.talk_check = false;
        self.meas = None;
        self.exec = None;
        self.out.clear();
        self.tx = None;
        self.lines.clear();
        self.inbuf.clear();
        tracing::debug!("simulated 34401A: device clear");
    }

    fn deaf(&self) -> bool {
        self.meas.as_ref().is_some_and(|m| m.dest == Dest::Memory)
    }

    fn line_arrived(&mut self, text: String, now: Instant) {
        self.counters.lines_seen += 1;
        let chars = u32::try_from(text.len() + 1).unwrap_or(u32::MAX);
        let ready_at = now.max(self.in_wire_free) + self.char_time() * chars;
        self.in_wire_free = ready_at;
        if self.deaf() {
            // only *TRG gets through while the meter waits for a bus trigger
            if let Some(m) = self.meas.as_mut()
                && m.awaiting_trigger
                && self.set.trig_source == TrigSource::Bus
                && text.trim().eq_ignore_ascii_case("*TRG")
            {
                m.awaiting_trigger = false;
                m.window_start = ready_at;
                m.done_at = ready_at;
                self.start_reading(ready_at);
                return;
            }
            self.lines.push_back(Line { text, ready_at });
            return;
        }
        if self.remote && self.query_pending() {
            let started = self.tx.is_some()
                || !self.out.is_empty()
                || self.exec.as_ref().is_some_and(|e| e.has_output);
            if started {
                self.raise(-410, "Query INTERRUPTED");
            } else {
                self.raise(-420, "Query UNTERMINATED");
            }
            self.meas = None;
            self.exec = None;
            self.out.clear();
            self.tx = None;
            self.lines.clear();
        }
        self.lines.push_back(Line { text, ready_at });
    }

    fn query_pending(&self) -> bool {
        self.tx.is_some()
            || !self.out.is_empty()
            || self.meas.as_ref().is_some_and(|m| m.dest == Dest::Output)
            || self
                .exec
                .as_ref()
                .is_some_and(|e| e.has_output || e.units.iter().any(|u| u.query))
            || self.lines.iter().any(|l| l.text.contains('?'))
    }

    fn raise(&mut self, code: i32, message: &str) {
        self.counters.errors_raised += 1;
        tracing::debug!(code, message, "simulated 34401A: error");
        self.errors.raise(code, message);
    }

    // ---- time --------------------------------------------------------------------------

    fn advance(&mut self, now: Instant) {
        match self.off_until {
            Some(t) if t <= now => self.power_on(t),
            Some(_) => return,
            None => {}
        }
        loop {
            let mut progressed = false;
            if let Some(m) = self.meas.as_mut()
                && m.blocked
                && self.out.len() + self.tx.as_ref().map_or(0, |t| t.0.len()) + 16
                    <= self.cfg.output_buffer
            {
                m.blocked = false;
                self.clock = self.clock.max(now);
                self.start_reading(now);
                progressed = true;
            }
            if let Some(m) = &self.meas
                && !m.blocked
                && !m.awaiting_trigger
                && m.done_at <= now
            {
                self.clock = self.clock.max(m.done_at);
                self.complete_reading();
                progressed = true;
            }
            if self.tx.is_none() && !self.out.is_empty() {
                let mut n = self.out.len().min(16);
                if self.gpib()
                    && let Some(lf) = self.out.iter().take(n).position(|&b| b == b'\n')
                {
                    // a chunk ends at the end of a message (where EOI goes)
                    n = lf + 1;
                }
                let chunk: Vec<u8> = self.out.drain(..n).collect();
                let start = self.out_time.max(self.out_wire_free);
                let due = start + self.char_time() * u32::try_from(n).unwrap_or(16);
                self.out_wire_free = due;
                self.tx = Some((chunk, due));
                progressed = true;
            }
            if self.meas.is_none() && self.run_exec(now) {
                progressed = true;
            }
            if !progressed {
                break;
            }
        }
        self.deferred_talk_check();
    }

    fn trigger_delay(&self) -> Duration {
        let d = match self.set.trig_delay {
            Some(d) => Duration::from_secs_f64(d),
            None if self.set.nplc >= 1.0 => Duration::from_micros(1500),
            None => Duration::from_micros(1000),
        };
        scaled(&self.cfg, d)
    }

    fn integration(&self) -> Duration {
        scaled(
            &self.cfg,
            Duration::from_secs_f64(self.set.nplc / f64::from(self.cfg.line_hz)),
        )
    }

    /// Starts the next reading at `t`: trigger delay, integration, autozero.
    fn start_reading(&mut self, t: Instant) {
        let delay = self.trigger_delay();
        let t_int = self.integration();
        let az = self.set.zero == Zero::On;
        if let Some(m) = self.meas.as_mut() {
            m.window_start = t + delay;
            m.done_at = t + delay + if az { t_int * 2 } else { t_int };
        }
    }

    fn begin_measurement(&mut self, dest: Dest, now: Instant) {
        let awaiting = self.set.trig_source != TrigSource::Imm;
        self.meas = Some(Meas {
            dest,
            left_in_set: self.set.samp_count,
            triggers_left: self.set.trig_count.saturating_sub(1),
            awaiting_trigger: awaiting,
            window_start: now,
            done_at: now,
            blocked: false,
            produced: 0,
        });
        if dest == Dest::Memory {
            self.memory.clear();
            self.memory_fault = None;
        }
        if !awaiting {
            let armed = now + scaled(&self.cfg, ARM_TIME);
            self.start_reading(armed);
        }
    }

    fn sample(&mut self, window_start: Instant) -> f64 {
        let v = self.source.volts(window_start, self.integration());
        let v = self.noise.add(v);
        let forced = self.overloads_left > 0;
        self.overloads_left = self.overloads_left.saturating_sub(1);
        clip(v, self.set.range, forced)
    }

    fn complete_reading(&mut self) {
        let Some(m) = self.meas.as_ref() else { return };
        let (dest, start, done_at, produced) = (m.dest, m.window_start, m.done_at, m.produced);
        if self.reading_faults(dest) {
            self.meas = None;
            return;
        }
        let v = self.sample(start);
        self.counters.readings_taken += 1;
        match dest {
            Dest::Memory => self.memory.push(v),
            Dest::Output => {
                let sep = if produced > 0 {
                    Some(b',')
                } else if self.exec.as_ref().is_some_and(|e| e.has_output) {
                    Some(b';')
                } else {
                    None
                };
                let mut bytes = Vec::with_capacity(17);
                bytes.extend(sep);
                bytes.extend_from_slice(format_reading(v).as_bytes());
                self.emit(&bytes);
            }
        }
        let room = self.out.len() + self.tx.as_ref().map_or(0, |t| t.0.len()) + 16
            <= self.cfg.output_buffer;
        let Some(m) = self.meas.as_mut() else { return };
        m.produced += 1;
        m.left_in_set = m.left_in_set.saturating_sub(1);
        if m.left_in_set == 0 {
            if m.triggers_left == 0 {
                self.meas = None;
                return;
            }
            m.triggers_left -= 1;
            m.left_in_set = self.set.samp_count;
            if self.set.trig_source != TrigSource::Imm {
                m.awaiting_trigger = true;
                return;
            }
        }
        if dest == Dest::Output && !room {
            m.blocked = true;
        } else {
            self.start_reading(done_at);
        }
    }

    // ---- output ------------------------------------------------------------------------

    /// Queues reply bytes of the current line, applying a pending reply fault.
    fn emit(&mut self, bytes: &[u8]) {
        if self.out.is_empty() {
            self.out_time = self.clock;
        }
        let Some(exec) = self.exec.as_mut() else {
            self.out.extend(bytes);
            return;
        };
        if !exec.has_output {
            exec.has_output = true;
            exec.fault = self.pending_reply_fault.pop_front();
        }
        if exec.muted {
            return;
        }
        match exec.fault.take() {
            None => self.out.extend(bytes),
            Some(fault) => {
                let (sent, muted) = fault.apply(bytes);
                self.out.extend(sent);
                exec.muted = muted;
            }
        }
    }

    fn reply(&mut self, text: &str) {
        self.counters.queries_answered += 1;
        if self.exec.as_ref().is_some_and(|e| e.has_output) {
            self.emit(b";");
        }
        self.emit(text.as_bytes());
    }

    // ---- execution ---------------------------------------------------------------------

    /// Runs the current line (or starts the next ready one); false when nothing could be done.
    fn run_exec(&mut self, now: Instant) -> bool {
        if self.exec.is_none() {
            if self.lines.front().is_none_or(|l| l.ready_at > now) {
                return false;
            }
            let Some(line) = self.lines.pop_front() else {
                return false;
            };
            self.clock = self.clock.max(line.ready_at);
            self.exec = Some(Exec {
                units: parse_line(&line.text).into(),
                has_output: false,
                fault: None,
                muted: false,
            });
        }
        while let Some(unit) = self.exec.as_mut().and_then(|e| e.units.pop_front()) {
            self.counters.commands_seen += 1;
            let t = self.clock.min(now);
            self.execute(&unit, t);
            self.scheduled_faults();
            if self.meas.is_some()
                || self.exec.is_none()
                || self.disconnect
                || self.off_until.is_some()
            {
                return true;
            }
        }
        if self.exec.as_ref().is_some_and(|e| e.has_output) {
            if self.gpib() {
                self.emit(b"\n");
            } else {
                self.emit(b"\r\n");
            }
        }
        self.exec = None;
        true
    }

    fn execute(&mut self, u: &Unit, now: Instant) {
        let Some(cmd) = u.cmd else {
            self.raise(-113, "Undefined header");
            return;
        };
        if self.gpib() && matches!(cmd, Cmd::Remote | Cmd::Rwlock | Cmd::Local) {
            // RS-232-only commands (see the module documentation)
            self.raise(-113, "Undefined header");
            return;
        }
        if !self.remote && !matches!(cmd, Cmd::Remote | Cmd::Rwlock) {
            match self.cfg.local_mode {
                LocalMode::Refuse => {
                    self.raise(550, "Command not allowed in local");
                    return;
                }
                LocalMode::Ignore => return,
                LocalMode::Obey => {}
            }
        }
        if let Err((code, msg)) = self.command(cmd, u, now) {
            self.raise(code, msg);
        }
    }
}

async fn sleep_until_opt(t: Option<Instant>) {
    match t {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

#[cfg(test)]
mod power_cycle_tests;
