//! The Modbus client under the Watlow F4 driver: `tokio-modbus` for the frames (RTU with its
//! CRC, TCP with its MBAP header), and around it the policy the chamber role promises,
//! written once here so the dialect stays about registers:
//!
//! - every transaction has a deadline (the reply timeout); a reply that never came is a
//!   [`crate::ChamberErrorKind::Timeout`], one that came but did not decode (a CRC error, a cut or
//!   malformed frame, a reply to another request) is [`crate::ChamberErrorKind::Garbled`];
//! - reads (idempotent) are asked again, `1 + retries` attempts in all, each noted for
//!   [`crate::Chamber::take_retries`]; a write is sent once ([`ModbusLink::write`]: a
//!   register whose write starts an action, such as the F4's "terminate profile", may have
//!   acted when its echo was lost) unless the caller says it is a level
//!   ([`ModbusLink::write_level`]: a setpoint, whose write sets the register to a value and
//!   means the same the second time, so it is written again after a lost or garbled echo,
//!   like a read is asked again);
//! - a Modbus exception reply is a definite answer ([`crate::ChamberErrorKind::Instrument`], naming the
//!   exception and the register), never asked again;
//! - stale input (a late reply to an attempt that timed out) is thrown away before each request,
//!   and after any failure the `tokio-modbus` client is built afresh over the same stream, so
//!   nothing half-read or half-sent survives into the next transaction.
//!
//! Why the stream is shared behind a tap rather than handed to `tokio-modbus` outright: its
//! client owns its transport for good, stops after a decoding error (its framed stream
//! returns end-of-stream once), and waits for ever on a frame whose CRC is wrong while it
//! hunts for the next frame start. Keeping the stream here lets the driver rebuild the client,
//! drain stale bytes, and tell a silent controller (no byte came) from a garbled one (bytes
//! came, no frame).

use std::fmt;
use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex, PoisonError};
use std::task::{Context as TaskContext, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio_modbus::client::{Client as _, Context};
use tokio_modbus::{ExceptionCode, Request, Response, Slave};

use crate::ChamberError;

/// A byte stream a Modbus client can run over: a serial port, a pseudo-terminal, a TCP
/// socket, an in-memory pipe.
pub trait ModbusStream: AsyncRead + AsyncWrite + Send + Unpin + 'static {}
impl<T: AsyncRead + AsyncWrite + Send + Unpin + 'static> ModbusStream for T {}

/// How the frames are built on the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// Modbus RTU (serial): slave address, PDU, CRC-16.
    Rtu,
    /// Modbus TCP: the MBAP header (transaction id, length, unit id) and the PDU, no CRC.
    Tcp,
}

/// The received bytes kept per transaction for the diagnosis of a garbled reply.
const TAP_KEEP: usize = 512;

struct Shared {
    stream: Box<dyn ModbusStream>,
    /// Bytes received since the last request (the first [`TAP_KEEP`]).
    received: Vec<u8>,
    /// How many bytes were received since the last request.
    received_count: usize,
}

fn lock(shared: &Mutex<Shared>) -> std::sync::MutexGuard<'_, Shared> {
    shared.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The stream as `tokio-modbus` sees it: the shared stream, with every byte read noted.
#[derive(Clone)]
struct Tap(Arc<Mutex<Shared>>);

impl fmt::Debug for Tap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Tap")
    }
}

impl AsyncRead for Tap {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut TaskContext<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let mut shared = lock(&self.0);
        let before = buf.filled().len();
        let result = Pin::new(&mut shared.stream).poll_read(cx, buf);
        if let Poll::Ready(Ok(())) = result {
            let new = &buf.filled()[before..];
            shared.received_count = shared.received_count.saturating_add(new.len());
            let room = TAP_KEEP.saturating_sub(shared.received.len());
            let keep = &new[..new.len().min(room)];
            shared.received.extend_from_slice(keep);
        }
        result
    }
}

impl AsyncWrite for Tap {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut TaskContext<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut lock(&self.0).stream).poll_write(cx, buf)
    }

    fn poll_flush(self: Pin<&mut Self>, cx: &mut TaskContext<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut lock(&self.0).stream).poll_flush(cx)
    }

    fn poll_shutdown(self: Pin<&mut Self>, cx: &mut TaskContext<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut lock(&self.0).stream).poll_shutdown(cx)
    }
}

/// A Modbus exception, as an operator reads it.
pub fn exception_text(code: ExceptionCode) -> String {
    let n = u8::from(code);
    let meaning = match n {
        1 => "illegal function",
        2 => "illegal data address",
        3 => "illegal data value",
        4 => "slave device failure",
        5 => "acknowledge",
        6 => "slave device busy",
        8 => "memory parity error",
        10 => "gateway path unavailable",
        11 => "gateway target device failed to respond",
        _ => "not a standard exception",
    };
    format!("Modbus exception {n} ({meaning})")
}

/// The Modbus RTU CRC-16 (polynomial 0xA001 reflected, initial 0xFFFF), as sent: low byte
/// first. Used only to say why a reply was garbled; `tokio-modbus` checks the frames.
pub fn crc16(data: &[u8]) -> [u8; 2] {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc.to_le_bytes()
}

/// Bytes as hex, for messages (at most 32 shown).
pub fn hex(bytes: &[u8]) -> String {
    let mut s: Vec<String> = bytes.iter().take(32).map(|b| format!("{b:02X}")).collect();
    if bytes.len() > 32 {
        s.push(format!("… ({} bytes)", bytes.len()));
    }
    s.join(" ")
}

/// Why a reply that came did not decode.
fn diagnose(framing: Framing, bytes: &[u8], count: usize) -> String {
    if framing == Framing::Rtu && bytes.len() >= 4 && bytes.len() == count {
        let (body, crc) = bytes.split_at(bytes.len() - 2);
        let computed = crc16(body);
        if crc != computed {
            return format!(
                "CRC error: {count} bytes [{}] end in {:02X} {:02X}, their CRC is {:02X} {:02X}",
                hex(bytes),
                crc[0],
                crc[1],
                computed[0],
                computed[1]
            );
        }
    }
    format!(
        "{count} bytes [{}] that are not a complete reply frame",
        hex(bytes)
    )
}

/// How one transaction failed.
enum Failure {
    /// A Modbus exception reply (definite).
    Exception(ExceptionCode),
    /// Bytes came that were not the reply (retried for reads).
    Garbled(String),
    /// Nothing came in time (retried for reads).
    Silent,
    /// The link itself failed (never retried).
    Link(String),
}

/// A Modbus client with the chamber's deadlines, retries and error kinds.
pub struct ModbusLink {
    shared: Arc<Mutex<Shared>>,
    ctx: Context,
    framing: Framing,
    slave: u8,
    device: String,
    timeout: Duration,
    retries: u32,
    retry_notes: Vec<String>,
    last_exception: Option<u8>,
}

impl fmt::Debug for ModbusLink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ModbusLink")
            .field("device", &self.device)
            .field("framing", &self.framing)
            .field("slave", &self.slave)
            .finish_non_exhaustive()
    }
}

fn attach(tap: Tap, framing: Framing, slave: u8) -> Context {
    match framing {
        Framing::Rtu => tokio_modbus::client::rtu::attach_slave(tap, Slave(slave)),
        Framing::Tcp => tokio_modbus::client::tcp::attach_slave(tap, Slave(slave)),
    }
}

/// What a request sent again is, for the note of each retry: a read is asked again, the
/// write of a level (a setpoint) written again with the same value.
#[derive(Debug, Clone, Copy)]
enum Repeat {
    Read,
    Level,
}

impl ModbusLink {
    /// A client over `stream` for `slave`.
    pub fn new(
        stream: Box<dyn ModbusStream>,
        framing: Framing,
        slave: u8,
        device: String,
        timeout: Duration,
        retries: u32,
    ) -> Self {
        let shared = Arc::new(Mutex::new(Shared {
            stream,
            received: Vec::new(),
            received_count: 0,
        }));
        let ctx = attach(Tap(Arc::clone(&shared)), framing, slave);
        ModbusLink {
            shared,
            ctx,
            framing,
            slave,
            device,
            timeout,
            retries,
            retry_notes: Vec::new(),
            last_exception: None,
        }
    }

    /// The link's description.
    pub fn device(&self) -> &str {
        &self.device
    }

    /// The exception code of the last transaction, if it was refused with one (lets a
    /// dialect fall back, e.g. from a block read to single reads).
    pub fn last_exception(&self) -> Option<u8> {
        self.last_exception
    }

    /// The retries since the last call.
    pub fn take_retries(&mut self) -> Vec<String> {
        std::mem::take(&mut self.retry_notes)
    }

    /// A fresh `tokio-modbus` client over the same stream.
    fn rebuild(&mut self) {
        self.ctx = attach(Tap(Arc::clone(&self.shared)), self.framing, self.slave);
    }

    /// Throws away whatever is waiting on the stream (a late reply), without waiting, and
    /// forgets the bytes noted so far.
    async fn drain(&mut self) {
        let shared = Arc::clone(&self.shared);
        std::future::poll_fn(move |cx| {
            let mut s = lock(&shared);
            let mut scratch = [0u8; 256];
            // Bounded: a peer that floods the line cannot hold the driver here.
            for _ in 0..64 {
                let mut buf = ReadBuf::new(&mut scratch);
                match Pin::new(&mut s.stream).poll_read(cx, &mut buf) {
                    Poll::Ready(Ok(())) if !buf.filled().is_empty() => {
                        tracing::debug!(dropped = buf.filled().len(), "stale Modbus input dropped");
                    }
                    _ => break,
                }
            }
            s.received.clear();
            s.received_count = 0;
            Poll::Ready(())
        })
        .await;
    }

    /// One request and its reply, within the deadline.
    async fn transact(&mut self, request: Request<'static>) -> Result<Response, Failure> {
        self.drain().await;
        self.last_exception = None;
        let outcome = tokio::time::timeout(self.timeout, self.ctx.call(request)).await;
        let failure = match outcome {
            Ok(Ok(Ok(response))) => return Ok(response),
            Ok(Ok(Err(exception))) => {
                self.last_exception = Some(u8::from(exception));
                return Err(Failure::Exception(exception));
            }
            Err(_elapsed) => {
                let s = lock(&self.shared);
                if s.received_count == 0 {
                    Failure::Silent
                } else {
                    Failure::Garbled(diagnose(self.framing, &s.received, s.received_count))
                }
            }
            Ok(Err(tokio_modbus::Error::Protocol(e))) => {
                Failure::Garbled(format!("a reply that does not answer this request ({e})"))
            }
            Ok(Err(tokio_modbus::Error::Transport(e))) => match e.kind() {
                io::ErrorKind::InvalidData => {
                    let s = lock(&self.shared);
                    Failure::Garbled(format!(
                        "{e}: {}",
                        diagnose(self.framing, &s.received, s.received_count)
                    ))
                }
                io::ErrorKind::BrokenPipe | io::ErrorKind::UnexpectedEof => {
                    Failure::Link("the link closed (end of stream)".into())
                }
                _ => Failure::Link(e.to_string()),
            },
        };
        self.rebuild();
        Err(failure)
    }

    fn exception_error(&self, request: &str, code: ExceptionCode) -> ChamberError {
        ChamberError::Instrument {
            device: self.device.clone(),
            request: request.to_string(),
            reason: exception_text(code),
        }
    }

    /// Reads `count` holding registers from `addr` (function 3), asked again on a lost or
    /// garbled reply.
    pub async fn read(&mut self, addr: u16, count: u16) -> Result<Vec<u16>, ChamberError> {
        let request = if count == 1 {
            format!("read register {addr}")
        } else {
            format!(
                "read registers {addr}..={}",
                addr.saturating_add(count.saturating_sub(1))
            )
        };
        self.idempotent(
            request,
            Request::ReadHoldingRegisters(addr, count),
            Repeat::Read,
            |reply| match reply {
                Response::ReadHoldingRegisters(words) if words.len() == usize::from(count) => {
                    Ok(words)
                }
                // A reply of another length: not this request's (never indexed past).
                Response::ReadHoldingRegisters(words) => {
                    Err(format!("{} registers instead of {count}", words.len()))
                }
                other => Err(format!("{other:?}")),
            },
        )
        .await
    }

    /// Sends `req` (named `request`) until `accept` takes its reply, `1 + retries` attempts in
    /// all, each attempt after the first noted for [`crate::Chamber::take_retries`] with what
    /// went wrong before it: for a request that means the same the second time (a read; the
    /// write of a level, [`Repeat`]). `accept` says why a decoded reply is not this request's
    /// (another function, another length, another echo): the link is rebuilt then, as after a
    /// garbled frame. An exception or a link failure ends it at once.
    async fn idempotent<T>(
        &mut self,
        request: String,
        req: Request<'static>,
        repeat: Repeat,
        accept: impl Fn(Response) -> Result<T, String>,
    ) -> Result<T, ChamberError> {
        let (reply, again) = match repeat {
            Repeat::Read => ("reply", "asked again"),
            Repeat::Level => ("echo", "written again, the same value"),
        };
        let attempts = self.retries.saturating_add(1);
        let mut last = String::new();
        let mut silent = true;
        for attempt in 1..=attempts {
            if attempt > 1 {
                let note = format!(
                    "{}: {request}: {last}; {again} (attempt {attempt} of {attempts})",
                    self.device
                );
                tracing::warn!("{note}");
                self.retry_notes.push(note);
            }
            match self.transact(req.clone()).await {
                Ok(response) => match accept(response) {
                    Ok(v) => return Ok(v),
                    Err(why) => {
                        silent = false;
                        last = format!("garbled {reply}: {why}");
                        self.rebuild();
                    }
                },
                Err(Failure::Exception(code)) => return Err(self.exception_error(&request, code)),
                Err(Failure::Link(detail)) => {
                    return Err(ChamberError::Link {
                        device: self.device.clone(),
                        request,
                        detail,
                    });
                }
                Err(Failure::Silent) => {
                    last = format!("no {reply} within {} ms", self.timeout.as_millis());
                }
                Err(Failure::Garbled(detail)) => {
                    silent = false;
                    last = format!("garbled {reply}: {detail}");
                }
            }
        }
        Err(self.final_error(request, silent, last, attempts))
    }

    fn final_error(
        &self,
        request: String,
        silent: bool,
        last: String,
        attempts: u32,
    ) -> ChamberError {
        if silent {
            ChamberError::Timeout {
                device: self.device.clone(),
                request: format!("{request} (asked {attempts} times; the chamber is silent)"),
                timeout_ms: u64::try_from(self.timeout.as_millis()).unwrap_or(u64::MAX),
            }
        } else {
            ChamberError::Garbled {
                device: self.device.clone(),
                request: format!("{request} (asked {attempts} times)"),
                detail: last,
            }
        }
    }

    /// Writes one holding register that holds a level (function 6: a setpoint), written
    /// again after a lost or garbled echo, `1 + retries` attempts in all, each noted for
    /// [`crate::Chamber::take_retries`].
    ///
    /// Why a write may be repeated here: function 6 sets the register to the value. If the
    /// first write was done and only its echo was corrupted on the way back (a CRC error, the
    /// one fault a noisy RS-485 line makes), the second sets it to the same value again: the
    /// controller ends in the same state either way (in the Modbus application protocol the
    /// echo of function 6 is sent after the register is written). Refusing to write it again
    /// ended a whole temperature series at one corrupted echo of one of the setpoints its
    /// ramps write at every poll (`series_faults_cli`). The caller still reads the register
    /// back. An exception is a definite answer and is never repeated.
    pub async fn write_level(&mut self, addr: u16, value: u16) -> Result<(), ChamberError> {
        let request = format!("write register {addr} = {} (0x{value:04X})", value as i16);
        self.idempotent(
            request,
            Request::WriteSingleRegister(addr, value),
            Repeat::Level,
            |reply| match reply {
                Response::WriteSingleRegister(a, v) if a == addr && v == value => Ok(()),
                other => Err(format!("{other:?} is not this write's")),
            },
        )
        .await
    }

    /// Writes one holding register (function 6), once: a write that starts an action (a
    /// command register) is never sent twice, since a write whose echo was lost may have
    /// been done.
    pub async fn write(&mut self, addr: u16, value: u16) -> Result<(), ChamberError> {
        let request = format!("write register {addr} = {} (0x{value:04X})", value as i16);
        match self
            .transact(Request::WriteSingleRegister(addr, value))
            .await
        {
            Ok(Response::WriteSingleRegister(a, v)) if a == addr && v == value => Ok(()),
            Ok(other) => {
                self.rebuild();
                Err(ChamberError::Garbled {
                    device: self.device.clone(),
                    request,
                    detail: format!("the echo {other:?} is not this write's (not sent again)"),
                })
            }
            Err(Failure::Exception(code)) => Err(self.exception_error(&request, code)),
            Err(Failure::Link(detail)) => Err(ChamberError::Link {
                device: self.device.clone(),
                request,
                detail,
            }),
            Err(Failure::Silent) => {
                Err(self.final_error(format!("{request}, not sent again"), true, String::new(), 1))
            }
            Err(Failure::Garbled(detail)) => Err(ChamberError::Garbled {
                device: self.device.clone(),
                request: format!("{request}, not sent again"),
                detail,
            }),
        }
    }
}

/// Bytes of a read of `count` registers: (request, reply), as framed.
pub fn read_frame_sizes(framing: Framing, count: u16) -> (u32, u32) {
    let data = 2 * u32::from(count);
    match framing {
        // slave, function, address (2), count (2), CRC (2) / slave, function, byte count, data, CRC
        Framing::Rtu => (8, 5 + data),
        // MBAP (7), function, address (2), count (2) / MBAP, function, byte count, data
        Framing::Tcp => (12, 9 + data),
    }
}

/// The bits of one RTU character: 1 start, 8 data, 1 stop (8N1, no parity).
pub const RTU_BITS_PER_CHAR: u32 = 10;

/// How long one transaction takes: both frames on the wire (RTU: 10 bits a character and the
/// 3.5-character silence that ends each frame; TCP: the gateway's wire time is in its latency)
/// plus the controller's reply latency.
pub fn transaction_time(
    framing: Framing,
    baud: u32,
    (request, reply): (u32, u32),
    latency: Duration,
) -> Duration {
    match framing {
        Framing::Rtu => {
            let char_s = f64::from(RTU_BITS_PER_CHAR) / f64::from(baud.max(1));
            let chars = f64::from(request + reply) + 2.0 * 3.5;
            Duration::from_secs_f64(chars * char_s) + latency
        }
        Framing::Tcp => latency,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_of_the_spec_example() {
        // Modbus over serial line, V1.02, appendix B: 02 07 has the CRC 41 12 (low byte first).
        assert_eq!(crc16(&[0x02, 0x07]), [0x41, 0x12]);
    }

    #[test]
    fn rtu_timing_counts_characters_and_gaps() {
        // A read of 9 registers at 9600 baud: 8 + 23 characters and two 3.5-character gaps,
        // 38 characters of 10 bits = 39.58 ms, plus the latency.
        let t = transaction_time(
            Framing::Rtu,
            9600,
            read_frame_sizes(Framing::Rtu, 9),
            Duration::from_millis(50),
        );
        let expected = 38.0 * 10.0 / 9600.0 + 0.050;
        assert!((t.as_secs_f64() - expected).abs() < 1e-9, "{t:?}");
    }
}
