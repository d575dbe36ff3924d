//! A simulated Prologix GPIB-USB / GPIB-ETHERNET controller in front of the simulated 34401A.
//!
//! [`SimPrologix::spawn`] serves the controller's host side (the USB serial port or the TCP
//! connection to port 1234: any async byte stream) and drives a GPIB "bus" stream to a meter
//! in GPIB mode ([`crate::dmm::Interface::Gpib`]); [`spawn_gpib_meter`] wires the two.
//!
//! Behaviour, from the Prologix user manual v6.107 as summarised in
//! `shared/docs/instruments.md`, and what the simulator chose where that says nothing:
//! - Input from the host is cut at unescaped CR or LF; ESC makes the next byte literal. A line
//!   starting with an unescaped `++` is a controller command; any other line is data for the
//!   instrument at `++addr`, sent with the `++eos` terminator (`++eos 2`: LF). Empty lines are
//!   ignored. Data for an address where no instrument listens is dropped.
//! - Commands: `++addr`, `++auto`, `++eoi`, `++eos`, `++eot_enable`, `++eot_char`, `++mode`,
//!   `++read_tmo_ms`, `++savecfg` set their value with an argument and answer it without one
//!   (out-of-range arguments are ignored: the simulator's choice); `++clr` sends Selected Device
//!   Clear; `++ifc` unaddresses the bus; `++read [eoi|<char>]` addresses the instrument to talk
//!   and forwards its bytes to the host until EOI (`eoi`: the meter's message-ending LF, which
//!   carries EOI), the character, or `++read_tmo_ms` without a byte (then the instrument is
//!   unaddressed); `++ver` answers [`PrologixConfig::version`]; `++spoll` and `++srq` answer
//!   `0` (status not modelled); `++loc`, `++llo`, `++trg`, `++rst` are accepted and not
//!   modelled beyond `++rst` restoring the defaults (without its 5 s pause). Replies to
//!   controller commands end CR LF.
//! - An unknown `++` command is answered `Unrecognized command` (CR LF): what the firmware
//!   answers as far as the simulator's sources go (unconfirmed; configurable as
//!   [`PrologixConfig::unknown_reply`], `None` for silence).
//! - `++auto 1`: after each data message the controller addresses the instrument to talk and
//!   reads as for `++read eoi`, so a non-query gets the meter's -420 "Query UNTERMINATED"
//!   queued (the meter models it: [`crate::dmm`]'s GPIB mode).
//! - Host input that arrives during a read ends the read (the instrument is unaddressed; what it
//!   had not sent stays in its output buffer) and is then processed (the simulator's choice,
//!   unconfirmed: a host that sends while a reply is in flight has given up on that reply).
//! - The host side has no timing (USB and Ethernet are fast next to the bus and the meter).

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::SignalSource;
use crate::dmm::{DmmConfig, DmmHandle, GPIB_SDC, GPIB_TALK, GPIB_UNTALK, Interface, SimDmm};

/// The escape byte.
const ESC: u8 = 0x1b;

/// The simulated controller's settings.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PrologixConfig {
    /// `++ver` reply. Default `Prologix GPIB-USB Controller version 6.107`.
    pub version: String,
    /// The GPIB address the instrument on the bus listens at. Default 22.
    pub instrument_addr: u8,
    /// Reply to an unknown `++` command (`None`: no reply). Default `Unrecognized command`.
    pub unknown_reply: Option<String>,
}

impl Default for PrologixConfig {
    fn default() -> Self {
        PrologixConfig {
            version: "Prologix GPIB-USB Controller version 6.107".into(),
            instrument_addr: 22,
            unknown_reply: Some("Unrecognized command".into()),
        }
    }
}

/// What the controller saw, for tests.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PrologixStats {
    /// Controller commands received, in order, as text (`++addr 22`).
    pub commands: Vec<String>,
    /// Data messages sent to the instrument.
    pub data_messages: u64,
    /// Reads begun (`++read` and `++auto 1` reads).
    pub reads: u64,
    /// Reads that ended on the read timeout.
    pub read_timeouts: u64,
    /// Reads ended by input from the host.
    pub reads_interrupted: u64,
    /// Selected Device Clears sent (`++clr`).
    pub clears: u64,
    /// Unknown `++` commands.
    pub unknown: u64,
    /// The settings now: `(addr, auto, eoi, eos, read_tmo_ms, savecfg)`.
    pub settings: (u8, bool, bool, u8, u32, bool),
}

/// Controls a running simulated controller.
pub struct PrologixHandle {
    stats: Arc<Mutex<PrologixStats>>,
    task: JoinHandle<()>,
}

impl PrologixHandle {
    /// A snapshot of what the controller saw.
    pub fn stats(&self) -> PrologixStats {
        self.stats.lock().map(|s| s.clone()).unwrap_or_default()
    }

    /// Stops the controller.
    pub fn abort(&self) {
        self.task.abort();
    }
}

/// The simulated controller.
pub struct SimPrologix;

impl SimPrologix {
    /// Serves the controller on `host`, with the instrument on `bus` (a meter in GPIB mode).
    pub fn spawn<H, B>(host: H, bus: B, config: PrologixConfig) -> PrologixHandle
    where
        H: AsyncRead + AsyncWrite + Send + Unpin + 'static,
        B: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let stats = Arc::new(Mutex::new(PrologixStats::default()));
        let ctl = Controller::new(config, stats.clone());
        let task = tokio::spawn(ctl.run(host, bus));
        PrologixHandle { stats, task }
    }
}

/// A simulated 34401A in GPIB mode behind a simulated controller serving `host`. `dmm`'s
/// interface is set to GPIB.
pub fn spawn_gpib_meter<H>(
    host: H,
    config: PrologixConfig,
    mut dmm: DmmConfig,
    source: Box<dyn SignalSource>,
    seed: u64,
) -> (PrologixHandle, DmmHandle)
where
    H: AsyncRead + AsyncWrite + Send + Unpin + 'static,
{
    dmm.interface = Interface::Gpib;
    let (bus_ctl, bus_dev) = tokio::io::duplex(64 * 1024);
    let meter = SimDmm::spawn(bus_dev, dmm, source, seed);
    let ctl = SimPrologix::spawn(host, bus_ctl, config);
    (ctl, meter)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ReadEnd {
    Eoi,
    Char(u8),
    Timeout,
}

struct Reading {
    end: ReadEnd,
    last: Instant,
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Event {
    Command(String),
    Data(Vec<u8>),
}

#[derive(Debug, Clone)]
struct Settings {
    addr: u8,
    auto: bool,
    eoi: bool,
    eos: u8,
    eot_enable: bool,
    eot_char: u8,
    mode: u8,
    read_tmo_ms: u32,
    savecfg: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            addr: 10,
            auto: false,
            eoi: true,
            eos: 0,
            eot_enable: false,
            eot_char: 0,
            mode: 1,
            read_tmo_ms: 500,
            savecfg: true,
        }
    }
}

struct Controller {
    cfg: PrologixConfig,
    set: Settings,
    stats: Arc<Mutex<PrologixStats>>,
    counters: PrologixStats,
    /// The line being received from the host: bytes and whether each was escaped.
    line: Vec<(u8, bool)>,
    escape: bool,
    events: VecDeque<Event>,
    reading: Option<Reading>,
    to_host: Vec<u8>,
    to_bus: Vec<u8>,
}

impl Controller {
    fn new(cfg: PrologixConfig, stats: Arc<Mutex<PrologixStats>>) -> Self {
        Controller {
            cfg,
            set: Settings::default(),
            stats,
            counters: PrologixStats::default(),
            line: Vec::new(),
            escape: false,
            events: VecDeque::new(),
            reading: None,
            to_host: Vec::new(),
            to_bus: Vec::new(),
        }
    }

    async fn run<H, B>(mut self, host: H, bus: B)
    where
        H: AsyncRead + AsyncWrite + Send + Unpin + 'static,
        B: AsyncRead + AsyncWrite + Send + Unpin + 'static,
    {
        let (mut hr, mut hw) = tokio::io::split(host);
        let (mut br, mut bw) = tokio::io::split(bus);
        let mut hbuf = [0u8; 1024];
        let mut bbuf = [0u8; 1024];
        loop {
            while self.reading.is_none()
                && let Some(ev) = self.events.pop_front()
            {
                self.event(ev);
            }
            self.publish();
            if !self.to_bus.is_empty() {
                let bytes = std::mem::take(&mut self.to_bus);
                if bw.write_all(&bytes).await.is_err() || bw.flush().await.is_err() {
                    break;
                }
            }
            if !self.to_host.is_empty() {
                let bytes = std::mem::take(&mut self.to_host);
                if hw.write_all(&bytes).await.is_err() || hw.flush().await.is_err() {
                    break;
                }
            }
            let timeout_at = self
                .reading
                .as_ref()
                .map(|r| r.last + Duration::from_millis(u64::from(self.set.read_tmo_ms)));
            tokio::select! {
                biased;
                r = br.read(&mut bbuf) => match r {
                    Ok(0) | Err(_) => break,
                    Ok(n) => self.bus_input(&bbuf[..n]),
                },
                r = hr.read(&mut hbuf) => match r {
                    Ok(0) | Err(_) => break,
                    Ok(n) => {
                        self.host_input(&hbuf[..n]);
                        if self.reading.is_some() && !self.events.is_empty() {
                            self.reading = None;
                            self.counters.reads_interrupted += 1;
                            self.to_bus.push(GPIB_UNTALK);
                        }
                    }
                },
                () = sleep_until_opt(timeout_at) => {
                    self.reading = None;
                    self.counters.read_timeouts += 1;
                    self.to_bus.push(GPIB_UNTALK);
                }
            }
        }
        let _ = hw.shutdown().await;
        let _ = bw.shutdown().await;
    }

    fn publish(&mut self) {
        let s = &self.set;
        self.counters.settings = (s.addr, s.auto, s.eoi, s.eos, s.read_tmo_ms, s.savecfg);
        if let Ok(mut st) = self.stats.lock() {
            *st = self.counters.clone();
        }
    }

    fn host_input(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if self.escape {
                self.escape = false;
                self.line.push((b, true));
                continue;
            }
            match b {
                ESC => self.escape = true,
                b'\r' | b'\n' => {
                    let line = std::mem::take(&mut self.line);
                    if line.is_empty() {
                        continue;
                    }
                    let command =
                        line.len() >= 2 && line[..2].iter().all(|&(c, e)| c == b'+' && !e);
                    let raw: Vec<u8> = line.into_iter().map(|(c, _)| c).collect();
                    self.events.push_back(if command {
                        Event::Command(String::from_utf8_lossy(&raw).into_owned())
                    } else {
                        Event::Data(raw)
                    });
                }
                _ => self.line.push((b, false)),
            }
        }
    }

    fn bus_input(&mut self, bytes: &[u8]) {
        let Some(r) = self.reading.as_mut() else {
            tracing::debug!(
                n = bytes.len(),
                "simulated Prologix: bus bytes outside a read dropped"
            );
            return;
        };
        r.last = Instant::now();
        for (i, &b) in bytes.iter().enumerate() {
            self.to_host.push(b);
            let done = match r.end {
                ReadEnd::Eoi => b == b'\n',
                ReadEnd::Char(c) => b == c,
                ReadEnd::Timeout => false,
            };
            if done {
                if r.end == ReadEnd::Eoi && self.set.eot_enable {
                    self.to_host.push(self.set.eot_char);
                }
                if let ReadEnd::Char(_) = r.end {
                    self.to_bus.push(GPIB_UNTALK);
                }
                if i + 1 < bytes.len() {
                    tracing::debug!("simulated Prologix: bytes after the end of a read dropped");
                }
                self.reading = None;
                return;
            }
        }
    }

    fn begin_read(&mut self, end: ReadEnd) {
        self.counters.reads += 1;
        if self.set.addr == self.cfg.instrument_addr {
            self.to_bus.push(GPIB_TALK);
        }
        self.reading = Some(Reading {
            end,
            last: Instant::now(),
        });
    }

    fn reply(&mut self, text: &str) {
        self.to_host.extend_from_slice(text.as_bytes());
        self.to_host.extend_from_slice(b"\r\n");
    }

    fn event(&mut self, ev: Event) {
        match ev {
            Event::Data(data) => {
                if self.set.mode != 1 {
                    return;
                }
                self.counters.data_messages += 1;
                if self.set.addr == self.cfg.instrument_addr {
                    self.to_bus.extend_from_slice(&data);
                    self.to_bus.extend_from_slice(match self.set.eos {
                        0 => b"\r\n",
                        1 => b"\r",
                        2 => b"\n",
                        _ => b"",
                    });
                } else {
                    tracing::debug!(
                        addr = self.set.addr,
                        "simulated Prologix: no listener at this address"
                    );
                }
                if self.set.auto {
                    self.begin_read(ReadEnd::Eoi);
                }
            }
            Event::Command(text) => self.command(&text),
        }
    }

    fn command(&mut self, text: &str) {
        self.counters.commands.push(text.to_string());
        let body = &text[2..];
        let mut words = body.split_whitespace();
        let name = words.next().unwrap_or("").to_ascii_lowercase();
        let arg = words.next();
        let num = arg.and_then(|a| a.parse::<u32>().ok());
        // query without an argument, set with an in-range one; otherwise ignored
        macro_rules! setting {
            ($field:expr, $max:expr, $conv:expr) => {{
                match (arg, num) {
                    (None, _) => {
                        let v = u32::from($field);
                        self.reply(&v.to_string());
                    }
                    (Some(_), Some(v)) if v <= $max => $field = $conv(v),
                    _ => {}
                }
            }};
        }
        match name.as_str() {
            "addr" => setting!(self.set.addr, 30, |v| u8::try_from(v).unwrap_or(0)),
            "auto" => setting!(self.set.auto, 1, |v| v == 1),
            "eoi" => setting!(self.set.eoi, 1, |v| v == 1),
            "eos" => setting!(self.set.eos, 3, |v| u8::try_from(v).unwrap_or(0)),
            "eot_enable" => setting!(self.set.eot_enable, 1, |v| v == 1),
            "eot_char" => setting!(self.set.eot_char, 255, |v| u8::try_from(v).unwrap_or(0)),
            "mode" => setting!(self.set.mode, 1, |v| u8::try_from(v).unwrap_or(1)),
            "savecfg" => setting!(self.set.savecfg, 1, |v| v == 1),
            "read_tmo_ms" => match (arg, num) {
                (None, _) => {
                    let v = self.set.read_tmo_ms;
                    self.reply(&v.to_string());
                }
                (Some(_), Some(v)) if (1..=3000).contains(&v) => self.set.read_tmo_ms = v,
                _ => {}
            },
            "clr" => {
                self.counters.clears += 1;
                if self.set.addr == self.cfg.instrument_addr {
                    self.to_bus.push(GPIB_SDC);
                }
            }
            "ifc" => self.to_bus.push(GPIB_UNTALK),
            "read" => {
                let end = match arg {
                    None => ReadEnd::Timeout,
                    Some(a) if a.eq_ignore_ascii_case("eoi") => ReadEnd::Eoi,
                    Some(_) => match num.and_then(|v| u8::try_from(v).ok()) {
                        Some(c) => ReadEnd::Char(c),
                        None => ReadEnd::Timeout,
                    },
                };
                self.begin_read(end);
            }
            "ver" => {
                let v = self.cfg.version.clone();
                self.reply(&v);
            }
            "spoll" | "srq" => self.reply("0"),
            "loc" | "llo" | "trg" | "help" => {}
            "rst" => self.set = Settings::default(),
            _ => {
                self.counters.unknown += 1;
                if let Some(r) = self.cfg.unknown_reply.clone() {
                    self.reply(&r);
                }
            }
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
mod tests {
    use super::*;
    use crate::signal::Constant;

    async fn read_until(host: &mut tokio::io::DuplexStream, want: &[u8]) -> Vec<u8> {
        let mut got = Vec::new();
        let mut buf = [0u8; 256];
        while !got.ends_with(want) {
            let n = tokio::time::timeout(Duration::from_secs(10), host.read(&mut buf))
                .await
                .expect("reply in time")
                .expect("read");
            assert!(n > 0, "closed");
            got.extend_from_slice(&buf[..n]);
        }
        got
    }

    fn meter() -> (tokio::io::DuplexStream, PrologixHandle, DmmHandle) {
        let (host, dev) = tokio::io::duplex(64 * 1024);
        let (ctl, dmm) = spawn_gpib_meter(
            dev,
            PrologixConfig::default(),
            DmmConfig::default(),
            Box::new(Constant(1.0)),
            1,
        );
        (host, ctl, dmm)
    }

    #[tokio::test(start_paused = true)]
    async fn ver_settings_and_unknown_commands() {
        let (mut host, ctl, _dmm) = meter();
        host.write_all(b"++ver\n").await.unwrap();
        assert_eq!(
            read_until(&mut host, b"\r\n").await,
            b"Prologix GPIB-USB Controller version 6.107\r\n"
        );
        host.write_all(b"++addr 22\n++addr\n++eos 2\r++eos 9\n++eos\n++frob\n")
            .await
            .unwrap();
        assert_eq!(
            read_until(&mut host, b"Unrecognized command\r\n").await,
            b"22\r\n2\r\nUnrecognized command\r\n"
        );
        let st = ctl.stats();
        assert_eq!(st.unknown, 1);
        assert_eq!(st.settings.0, 22);
        assert_eq!(st.settings.3, 2);
    }

    #[tokio::test(start_paused = true)]
    async fn query_waits_for_read_and_needs_no_syst_rem() {
        let (mut host, ctl, dmm) = meter();
        host.write_all(b"++addr 22\n++auto 0\n++eos 2\n*IDN?\n")
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_secs(1)).await;
        // nothing is sent before the read
        let mut buf = [0u8; 64];
        assert!(
            tokio::time::timeout(Duration::from_millis(10), host.read(&mut buf))
                .await
                .is_err()
        );
        host.write_all(b"++read eoi\n").await.unwrap();
        assert_eq!(
            read_until(&mut host, b"\n").await,
            b"HEWLETT-PACKARD,34401A,0,11-5-2\n"
        );
        assert!(dmm.stats().remote);
        assert_eq!(ctl.stats().reads, 1);
        // escaped bytes reach the meter as data: an escaped LF ends no message
        host.write_all(b"SYST:ERR?\n++read eoi\n").await.unwrap();
        assert_eq!(read_until(&mut host, b"\n").await, b"+0,\"No error\"\n");
    }

    #[tokio::test(start_paused = true)]
    async fn auto_read_after_a_command_gives_420_and_clr_clears() {
        let (mut host, ctl, dmm) = meter();
        host.write_all(b"++addr 22\n++eos 2\n++read_tmo_ms 200\n++auto 1\n*CLS\n")
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_secs(1)).await;
        assert_eq!(ctl.stats().read_timeouts, 1);
        host.write_all(b"++auto 0\nSYST:ERR?\n++read eoi\n")
            .await
            .unwrap();
        assert_eq!(
            read_until(&mut host, b"\n").await,
            b"-420,\"Query UNTERMINATED\"\n"
        );
        // RS-232-only commands are refused over GPIB
        host.write_all(b"SYST:REM\nSYST:ERR?\n++read eoi\n")
            .await
            .unwrap();
        assert_eq!(
            read_until(&mut host, b"\n").await,
            b"-113,\"Undefined header\"\n"
        );
        host.write_all(b"++clr\n").await.unwrap();
        tokio::time::sleep(Duration::from_millis(10)).await;
        assert_eq!(dmm.stats().device_clears, 1);
        assert_eq!(ctl.stats().clears, 1);
    }
}
