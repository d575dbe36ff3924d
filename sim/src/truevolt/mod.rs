//! A simulated Keysight Truevolt (34460A / 34461A / 34465A / 34470A) on its LAN SCPI socket.
//!
//! [`SimTruevolt::spawn`] runs the instrument as a tokio task; connections reach it through a
//! [`LanPort`]: an in-memory pipe per connection in virtual time ([`LanPort::connector`], what
//! a [`gyrocal_link::SocketTransport`] reconnects through), or accepted TCP sockets in
//! `gyrocal sim` ([`LanPort::attach`]). One connection is served at a time, the newest: a
//! client that reconnects (the socket's device clear) takes over, and the output owed to the
//! old connection is dropped. The instrument's state (settings, a measurement in progress,
//! the reading memory, the error queue) belongs to the instrument, not to a connection.
//!
//! The wire protocol (facts from `shared/docs/instruments.md`, the model facts and the timing
//! from [`gyrocal_truevolt`], so the simulator and the driver's estimate agree by
//! construction):
//!
//! - lines end in LF; `;` separates commands (each taken from the root: a simplification),
//!   long and short forms, case-insensitive, the optional `[:SENSe]` and `[:DC]` nodes;
//! - `*IDN?` (as the model, or as `HEWLETT-PACKARD,34401A,...` after `SYST:IDEN HP34401A`;
//!   `SYST:IDEN DEF` undoes it; the setting survives `*RST` and power cycles), `*RST`, `*CLS`,
//!   `*OPC?` (answers once the measurement is over), `*ESR?` (Power On bit 128 only),
//!   `SYST:ERR?` (a 20-entry SCPI queue: -113 undefined header, -222 data out of range, ...),
//!   `SYST:IDEN?`;
//! - `CONF:VOLT:DC [range|AUTO]`, `VOLT:DC:RANG`, `VOLT:DC:RANG:AUTO`, `VOLT:DC:NPLC` (values
//!   the model lacks: -222), `VOLT:DC:ZERO:AUTO`, `TRIG:SOUR` (IMM only is modelled),
//!   `TRIG:DEL`, `TRIG:DEL:AUTO`, `TRIG:COUN` (1 only), `SAMP:COUN`;
//! - `INIT` (clears the memory, then readings go into it, paced by the timing model:
//!   arming, then `delay + NPLC/f·(2 if autozero)` per reading), `ABOR`, `READ?` (`INIT` and
//!   `FETC?`), `FETC?` (waits for the end, sends the memory without erasing it),
//!   `R? [max]` (an IEEE 488.2 definite-length block, erasing what it sends, not waiting),
//!   `DATA:REMove? n[,WAIT]` (erases the n oldest; with `WAIT` waits until n are there),
//!   `DATA:POINts?`, `DATA:LAST?`, `STAT:QUES:COND?`, `STAT:QUES[:EVEN]?`;
//! - the memory holds the model's readings (2,000,000 with the MEM option); on overflow the
//!   oldest reading is overwritten and Questionable Data bit 14 (16384) is set; memory is
//!   cleared by `INIT`, `READ?`, `*RST` and configuration changes;
//! - replies carrying readings leave after their transfer time
//!   ([`gyrocal_truevolt::TimingDefaults::transfer_per_reading`] a reading), while the meter
//!   goes on measuring; other replies at once;
//! - every reading is the [`SignalSource`] averaged over its integration window (the gyro on
//!   the table at that instant), plus seeded gaussian noise.
//!
//! Faults ([`Fault`], through the same [`DmmHandle`] as the 34401A's, so `dmm:` fault specs
//! apply): `NoReply`, `Garble`, `Truncate` hit the next reply, or (armed at a reading) the
//! reply that carries that reading; `Overload`; `Disconnect` closes the connection and ends
//! the instrument for good (no more connections); `PowerCycle` kills the connection, keeps
//! the meter off for the off time (input ignored, nothing sent) and brings it back with the
//! `*RST` settings, an empty memory and error queue, and the Power On bit set; `PushError`;
//! `Slow` sends each reply its delay late (the meter executes nothing meanwhile, as a busy
//! instrument), on the connection the query came on: a reconnect drops it with the rest of
//! what the old connection was owed.
//!
//! Where it lives: this module holds the instrument's state, its connections, measurement and
//! replies; `commands` the command set. What it shares with the simulated 34401A (the error
//! queue, the fault grammar and [`DmmHandle`], reply faults, noise, reading format) is in
//! [`crate::scpi`].

mod commands;

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use gyrocal_link::{Connector, DynStream, LinkError};
use gyrocal_truevolt::{Model, TimingDefaults, TruevoltTiming};
use serde::{Deserialize, Serialize};
use tokio::io::{AsyncReadExt, AsyncWriteExt, ReadHalf, WriteHalf};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::SignalSource;
use crate::scpi::{
    ArmedFaults, Ctl, DmmHandle, DmmStats, ErrorQueue, EventStatus, Fault, Noise, ReplyFault,
    SlowReplies, clip, format_reading, slow_delay,
};
use commands::canonical;

/// Questionable Data register: memory overflow.
const QUES_MEMORY_OVERFLOW: u16 = 1 << 14;

/// What `*IDN?` answers as (`SYSTem:IDENtify`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Personality {
    /// The model itself (`DEF`).
    #[default]
    Def,
    /// An HP 34401A (`HP34401A`).
    Hp34401a,
}

/// The simulated Truevolt's configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TruevoltConfig {
    /// The model. Default 34461A.
    pub model: Model,
    /// The MEM option (34465A/70A). Default false.
    pub mem_option: bool,
    /// The `SYST:IDEN` setting at start. Default `def`.
    pub personality: Personality,
    /// Serial number in `*IDN?`. Default `MY00000001`.
    pub serial: String,
    /// The timing figures (the driver's defaults unless told otherwise).
    pub timing: TimingDefaults,
    /// Power-line frequency, Hz. Default 50.
    pub line_hz: u32,
    /// Standard deviation of the reading noise, V. Default 1 µV.
    pub noise_v: f64,
    /// Off time of a power cycle without its own, sim seconds. Default 5.
    pub power_off_s: f64,
    /// Sim seconds per real second. Default 1.
    pub time_scale: f64,
}

impl Default for TruevoltConfig {
    fn default() -> Self {
        TruevoltConfig {
            model: Model::M34461A,
            mem_option: false,
            personality: Personality::Def,
            serial: "MY00000001".into(),
            timing: TimingDefaults::default(),
            line_hz: 50,
            noise_v: 1e-6,
            power_off_s: 5.0,
            time_scale: 1.0,
        }
    }
}

/// Where connections to a simulated Truevolt come in.
#[derive(Clone)]
pub struct LanPort {
    tx: mpsc::UnboundedSender<DynStream>,
    name: String,
}

impl std::fmt::Debug for LanPort {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LanPort").field("name", &self.name).finish()
    }
}

impl LanPort {
    /// Hands the instrument a new connection (an accepted TCP socket); false when the
    /// instrument is gone.
    pub fn attach(&self, stream: DynStream) -> bool {
        self.tx.send(stream).is_ok()
    }

    /// Opens a new in-memory connection to the instrument: what a
    /// [`gyrocal_link::SocketTransport`] reconnects through in virtual time. Fails as a
    /// disconnect once the instrument is gone.
    pub fn connector(&self) -> Connector {
        let tx = self.tx.clone();
        let name = self.name.clone();
        Arc::new(move || {
            let tx = tx.clone();
            let name = name.clone();
            Box::pin(async move {
                let (host, dev) = tokio::io::duplex(64 * 1024);
                tx.send(Box::new(dev))
                    .map_err(|_| LinkError::Disconnected {
                        device: name,
                        partial: Vec::new(),
                    })?;
                Ok(Box::new(host) as DynStream)
            })
        })
    }
}

/// The simulated Truevolt.
pub struct SimTruevolt;

impl SimTruevolt {
    /// Runs the instrument; `first` is served as its first connection (if any). Returns its
    /// handle (faults, counters, stop) and its port for more connections.
    pub fn spawn(
        config: TruevoltConfig,
        first: Option<DynStream>,
        source: Box<dyn SignalSource>,
        seed: u64,
    ) -> (DmmHandle, LanPort) {
        let (ctl_tx, ctl_rx) = mpsc::unbounded_channel();
        let (conn_tx, conn_rx) = mpsc::unbounded_channel();
        let stats = Arc::new(Mutex::new(DmmStats::default()));
        let port = LanPort {
            tx: conn_tx,
            name: format!("sim-{}", config.model.key()),
        };
        if let Some(s) = first {
            port.attach(s);
        }
        let meter = Meter::new(config, source, seed, stats.clone());
        let task = tokio::spawn(meter.run(ctl_rx, conn_rx));
        (DmmHandle::from_parts(ctl_tx, stats, task), port)
    }
}

#[derive(Debug, Clone, PartialEq)]
struct Settings {
    range: Option<f64>,
    nplc: f64,
    autozero: bool,
    trig_delay: Option<f64>,
    samp_count: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            range: None,
            nplc: 10.0,
            autozero: true,
            trig_delay: None,
            samp_count: 1,
        }
    }
}

/// A measurement in progress: readings `taken` of `count`, the first done at `first_done`,
/// one every `every`.
struct Meas {
    count: usize,
    taken: usize,
    first_done: Instant,
    every: Duration,
    window: Duration,
}

impl Meas {
    fn done_at(&self, i: usize) -> Instant {
        self.first_done + self.every * u32::try_from(i).unwrap_or(u32::MAX)
    }
}

/// A query waiting for readings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Waiting {
    Opc,
    Fetch,
    Remove(usize),
}

type Conn = (ReadHalf<DynStream>, WriteHalf<DynStream>);

struct Meter {
    cfg: TruevoltConfig,
    source: Box<dyn SignalSource>,
    noise: Noise,
    stats: Arc<Mutex<DmmStats>>,
    counters: DmmStats,
    set: Settings,
    personality: Personality,
    errors: ErrorQueue,
    /// (value, reading number from 1)
    memory: VecDeque<(f64, u64)>,
    ques: u16,
    esr: EventStatus,
    meas: Option<Meas>,
    waiting: Option<Waiting>,
    lines: VecDeque<String>,
    inbuf: Vec<u8>,
    /// A reply ready to leave at the instant given.
    out: Option<(Vec<u8>, Instant)>,
    next_reply_fault: VecDeque<ReplyFault>,
    marked: HashMap<u64, ReplyFault>,
    at_reading: ArmedFaults,
    overloads_left: u32,
    off_until: Option<Instant>,
    /// A [`Fault::Slow`] in force: the delay, and the replies it still holds back.
    slow: SlowReplies,
    gone: bool,
    stop: bool,
}

impl Meter {
    fn new(
        cfg: TruevoltConfig,
        source: Box<dyn SignalSource>,
        seed: u64,
        stats: Arc<Mutex<DmmStats>>,
    ) -> Self {
        let noise = Noise::new(cfg.noise_v, seed);
        Meter {
            personality: cfg.personality,
            cfg,
            source,
            noise,
            stats,
            counters: DmmStats {
                remote: true,
                powered: true,
                nplc: 10.0,
                ..DmmStats::default()
            },
            set: Settings::default(),
            errors: ErrorQueue::default(),
            memory: VecDeque::new(),
            ques: 0,
            esr: EventStatus::powered_on(),
            meas: None,
            waiting: None,
            lines: VecDeque::new(),
            inbuf: Vec::new(),
            out: None,
            next_reply_fault: VecDeque::new(),
            marked: HashMap::new(),
            at_reading: ArmedFaults::default(),
            overloads_left: 0,
            off_until: None,
            slow: SlowReplies::default(),
            gone: false,
            stop: false,
        }
    }

    fn scaled(&self, d: Duration) -> Duration {
        let s = self.cfg.time_scale;
        if s.is_finite() && s > 0.0 {
            d.div_f64(s)
        } else {
            d
        }
    }

    fn timing(&self) -> TruevoltTiming {
        TruevoltTiming {
            model: self.cfg.model,
            memory: self.capacity(),
            nplc: self.set.nplc,
            line_hz: self.cfg.line_hz,
            autozero: self.set.autozero,
            trigger_delay: self
                .set
                .trig_delay
                .and_then(|d| Duration::try_from_secs_f64(d).ok()),
            defaults: self.cfg.timing,
            acquisition: gyrocal_truevolt::Acquisition::Stream,
        }
    }

    fn capacity(&self) -> usize {
        self.cfg.model.memory(self.cfg.mem_option)
    }

    async fn run(
        mut self,
        mut ctl: mpsc::UnboundedReceiver<Ctl>,
        mut conns: mpsc::UnboundedReceiver<DynStream>,
    ) {
        let mut conn: Option<Conn> = None;
        let mut buf = vec![0u8; 4096];
        let mut ctl_open = true;
        let mut conns_open = true;
        loop {
            let now = Instant::now();
            self.advance(now);
            if !conns_open && conn.is_none() {
                // nobody can reach the instrument any more
                break;
            }
            if self.off_until.is_some() || self.gone {
                // a dead meter's socket is gone
                conn = None;
            }
            if self.gone || self.stop {
                break;
            }
            if self.off_until.is_none() {
                self.execute(now);
            }
            if let Some((bytes, due)) = self.out.take_if(|(_, due)| *due <= now) {
                let _ = due;
                if let Some((_, wr)) = conn.as_mut() {
                    let ok = wr.write_all(&bytes).await.is_ok() && wr.flush().await.is_ok();
                    if !ok {
                        conn = None;
                    }
                }
                continue;
            }
            self.publish();
            let wake = self.next_wake();
            tokio::select! {
                biased;
                c = ctl.recv(), if ctl_open => match c {
                    Some(Ctl::Fault(f)) => self.inject(f, Instant::now()),
                    Some(Ctl::AtReading(n, f)) => self.at_reading.arm(n, f),
                    Some(Ctl::Stop) => self.stop = true,
                    None => ctl_open = false,
                },
                c = conns.recv(), if conns_open => match c {
                    Some(s) => {
                        // the newest connection takes over: what the old one was owed is gone
                        self.counters.device_clears += 1;
                        self.inbuf.clear();
                        self.lines.clear();
                        self.out = None;
                        self.waiting = None;
                        conn = Some(tokio::io::split(s));
                    }
                    None => conns_open = false,
                },
                r = async {
                    match conn.as_mut() {
                        Some((rd, _)) => rd.read(&mut buf).await,
                        None => std::future::pending().await,
                    }
                } => match r {
                    Ok(0) | Err(_) => conn = None,
                    Ok(n) => {
                        if self.off_until.is_none() {
                            let bytes = buf[..n].to_vec();
                            self.input(&bytes);
                        }
                    }
                },
                () = async {
                    match wake {
                        Some(t) => tokio::time::sleep_until(t).await,
                        None => std::future::pending().await,
                    }
                } => {}
            }
        }
        if let Some((_, mut wr)) = conn {
            let _ = wr.shutdown().await;
        }
        self.counters.stopped = true;
        self.publish();
        tracing::debug!("simulated Truevolt stopped");
    }

    fn publish(&mut self) {
        self.counters.powered = self.off_until.is_none();
        self.counters.nplc = self.set.nplc;
        self.counters.memory_points = self.memory.len();
        self.counters.error_queue = self.errors.snapshot();
        if let Ok(mut s) = self.stats.lock() {
            *s = self.counters.clone();
        }
    }

    fn next_wake(&self) -> Option<Instant> {
        let mut wake = self.off_until;
        let mut earliest = |t: Instant| {
            wake = Some(wake.map_or(t, |w: Instant| w.min(t)));
        };
        if let Some((_, due)) = &self.out {
            earliest(*due);
        }
        if let Some(m) = &self.meas {
            earliest(m.done_at(m.taken));
        }
        wake
    }

    fn input(&mut self, bytes: &[u8]) {
        self.inbuf.extend_from_slice(bytes);
        while let Some(pos) = self.inbuf.iter().position(|&b| b == b'\n') {
            let line: Vec<u8> = self.inbuf.drain(..=pos).collect();
            let text = String::from_utf8_lossy(&line[..pos]).trim().to_string();
            self.counters.lines_seen += 1;
            if !text.is_empty() {
                self.lines.push_back(text);
            }
        }
    }

    fn raise(&mut self, code: i32, message: &str) {
        self.counters.errors_raised += 1;
        self.errors.raise(code, message);
    }

    // ---- measurement -------------------------------------------------------------------

    fn advance(&mut self, now: Instant) {
        if let Some(t) = self.off_until
            && now >= t
        {
            self.power_on();
        }
        while let Some(m) = &self.meas {
            if m.taken >= m.count {
                self.meas = None;
                break;
            }
            let done = m.done_at(m.taken);
            if done > now || self.off_until.is_some() {
                break;
            }
            let window = m.window;
            self.take_reading(done, window);
        }
    }

    fn take_reading(&mut self, done: Instant, window: Duration) {
        let number = self.counters.readings_taken + 1;
        // faults armed for this reading; a power cycle or a disconnect takes the reading's
        // place, and the faults after it stay armed
        let mut due = self.at_reading.due(number).into_iter();
        while let Some(f) = due.next() {
            if let Some(reply_fault) = ReplyFault::of(&f) {
                self.marked.insert(number, reply_fault);
                continue;
            }
            match f {
                Fault::PowerCycle { off_s } => {
                    self.at_reading.put_back(number, due);
                    self.power_off(off_s, done);
                    return;
                }
                Fault::Disconnect => {
                    self.at_reading.put_back(number, due);
                    self.gone = true;
                    return;
                }
                f => self.inject(f, done),
            }
        }
        let start = done.checked_sub(window).unwrap_or(done);
        let v = self.noise.add(self.source.volts(start, window));
        let forced = self.overloads_left > 0;
        self.overloads_left = self.overloads_left.saturating_sub(1);
        let v = clip(v, self.set.range, forced);
        self.counters.readings_taken = number;
        if self.memory.len() >= self.capacity() {
            self.memory.pop_front();
            self.ques |= QUES_MEMORY_OVERFLOW;
        }
        self.memory.push_back((v, number));
        if let Some(m) = self.meas.as_mut() {
            m.taken += 1;
        }
    }

    fn start_measurement(&mut self, now: Instant) {
        self.memory.clear();
        let t = self.timing();
        let every = self.scaled(t.reading_time());
        let arm = self.scaled(t.defaults.arm_time);
        let window = self.scaled(if t.autozero {
            t.integration() * 2
        } else {
            t.integration()
        });
        self.meas = Some(Meas {
            count: self.set.samp_count,
            taken: 0,
            first_done: now + arm + every,
            every,
            window,
        });
    }

    fn power_off(&mut self, off_s: Option<f64>, at: Instant) {
        let off = off_s.unwrap_or(self.cfg.power_off_s).max(0.0);
        self.off_until = Some(at + self.scaled(Duration::from_secs_f64(off)));
        self.counters.power_cycles += 1;
        self.meas = None;
        self.waiting = None;
        self.out = None;
        self.lines.clear();
        self.inbuf.clear();
        tracing::info!("simulated Truevolt switched off");
    }

    fn power_on(&mut self) {
        self.off_until = None;
        self.set = Settings::default();
        self.memory.clear();
        self.errors.clear();
        self.ques = 0;
        self.esr = EventStatus::powered_on();
        tracing::info!("simulated Truevolt back on");
    }

    fn inject(&mut self, f: Fault, at: Instant) {
        if let Some(reply_fault) = ReplyFault::of(&f) {
            self.next_reply_fault.push_back(reply_fault);
            return;
        }
        match f {
            Fault::NoReply | Fault::Garble | Fault::Truncate => {}
            Fault::Disconnect => self.gone = true,
            Fault::Overload { readings } => self.overloads_left += readings,
            Fault::PowerCycle { off_s } => self.power_off(off_s, at),
            Fault::PushError { code, message } => self.raise(code, &message),
            Fault::Slow { delay_s, replies } => {
                self.slow.set(self.scaled(slow_delay(delay_s)), replies);
            }
        }
    }

    // ---- replies -----------------------------------------------------------------------

    /// Queues a reply (terminated here) carrying the readings numbered `numbers`, to leave
    /// after their transfer.
    fn reply(&mut self, text: String, numbers: &[u64], now: Instant) {
        self.counters.queries_answered += 1;
        let mut fault = self.next_reply_fault.pop_front();
        for n in numbers {
            if let Some(f) = self.marked.remove(n) {
                fault = fault.or(Some(f));
            }
        }
        let mut bytes = text.into_bytes();
        bytes.push(b'\n');
        let bytes = match fault {
            None => bytes,
            Some(ReplyFault::NoReply) => return,
            Some(fault) => fault.apply(&bytes).0,
        };
        let transfer = self.scaled(self.cfg.timing.transfer_per_reading)
            * u32::try_from(numbers.len()).unwrap_or(u32::MAX);
        // a slow meter sends its reply late, and executes nothing meanwhile
        let late = match self.slow.hold(1) {
            Some(delay) => {
                self.counters.late_replies += 1;
                delay
            }
            None => Duration::ZERO,
        };
        self.out = Some((bytes, now + transfer + late));
    }

    fn readings_text(items: &[(f64, u64)]) -> String {
        items
            .iter()
            .map(|(v, _)| format_reading(*v))
            .collect::<Vec<_>>()
            .join(",")
    }

    // ---- execution ---------------------------------------------------------------------

    /// Runs what can run now: a waiting query, then the next lines, until a query waits or a
    /// reply is on its way.
    fn execute(&mut self, now: Instant) {
        loop {
            if self.out.is_some() {
                return;
            }
            if let Some(w) = self.waiting {
                if !self.serve_waiting(w, now) {
                    return;
                }
                self.waiting = None;
                continue;
            }
            let Some(line) = self.lines.pop_front() else {
                return;
            };
            for unit in line.split(';') {
                if !unit.trim().is_empty() {
                    self.command(unit.trim(), now);
                }
            }
        }
    }

    /// Answers `w` if it can be answered now.
    fn serve_waiting(&mut self, w: Waiting, now: Instant) -> bool {
        let measuring = self.meas.is_some();
        match w {
            Waiting::Opc => {
                if measuring {
                    return false;
                }
                self.reply("1".into(), &[], now);
            }
            Waiting::Fetch => {
                if measuring {
                    return false;
                }
                if self.memory.is_empty() {
                    self.raise(-230, "Data corrupt or stale");
                    return true;
                }
                let items: Vec<(f64, u64)> = self.memory.iter().copied().collect();
                let numbers: Vec<u64> = items.iter().map(|i| i.1).collect();
                self.reply(Self::readings_text(&items), &numbers, now);
            }
            Waiting::Remove(n) => {
                if self.memory.len() < n {
                    if measuring {
                        return false;
                    }
                    // the measurement ended short of n readings: they will never come
                    self.raise(-222, "Data out of range");
                    return true;
                }
                let items: Vec<(f64, u64)> = self.memory.drain(..n).collect();
                let numbers: Vec<u64> = items.iter().map(|i| i.1).collect();
                self.reply(Self::readings_text(&items), &numbers, now);
            }
        }
        true
    }

    fn config_changed(&mut self) {
        self.memory.clear();
        self.meas = None;
    }

    fn command(&mut self, unit: &str, now: Instant) {
        self.counters.commands_seen += 1;
        let (header, params) = match unit.split_once(char::is_whitespace) {
            Some((h, p)) => (h, p.trim()),
            None => (unit, ""),
        };
        let params: Vec<&str> = if params.is_empty() {
            Vec::new()
        } else {
            params.split(',').map(str::trim).collect()
        };
        if let Err((code, msg)) = self.run_command(&canonical(header), &params, now) {
            self.raise(code, msg);
        }
    }
}
