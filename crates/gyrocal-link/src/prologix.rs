//! [`PrologixTransport`]: an instrument on GPIB behind a Prologix GPIB-USB (a USB serial port)
//! or GPIB-ETHERNET (TCP port 1234) controller, as a [`Transport`] wrapping the byte link to the
//! controller.
//!
//! Facts from the Prologix user manual (v6.107) as summarised in `shared/docs/instruments.md`:
//! controller commands start with `++` and end with CR or LF; every other line goes to the
//! instrument at the current address, with CR, LF, ESC and `+` escaped by ESC.
//!
//! What this transport does, and why:
//! - **At open** ([`PrologixTransport::open`]): stale input thrown away, then `++savecfg 0`
//!   first (the settings that follow are not written to the controller's EEPROM on every
//!   change), `++mode 1` (controller), `++ifc` (interface clear: the controller becomes
//!   controller-in-charge and every device on the bus is unaddressed, whatever a previous
//!   program left), `++addr N`, `++auto 0`, `++eoi 1` (EOI with the last byte sent), `++eos 2`,
//!   `++eot_enable 0` (nothing appended to replies: a previous user may have saved it on),
//!   `++read_tmo_ms T`, then `++ver`, whose answer proves that a controller is there.
//! - **`++eos 2` (LF)**: the controller appends LF to every message to the instrument. The
//!   34401A ends a GPIB message on LF or EOI, and LF is what the RS-232 driver already sends,
//!   so the same command strings work on both links; with `++eoi 1` EOI comes with it.
//! - **Queries**: never `++auto 1` (read-after-write on a non-query provokes -420 "Query
//!   UNTERMINATED" on the 34401A). A line is sent as data; the first read after it sends
//!   `++read eoi` (the instrument is addressed to talk and the controller forwards its bytes
//!   until EOI), then the reply is read. The instrument's GPIB replies end in LF with EOI, so
//!   the inner link's line framing applies unchanged.
//! - **Long waits** (`INIT;*OPC?`, a slow `READ?` stream): the controller gives up a read after
//!   `read_tmo_ms` without a character (at most 3 s), long before a burst ends. While a read
//!   is outstanding and nothing has arrived for `read_tmo_ms` plus a margin, the transport
//!   sends `++read eoi` again (re-arms) until the caller's own timeout. It re-arms only after
//!   such a silence, so it never talks to the controller while bytes are flowing.
//! - **Device clear** is `++clr` (Selected Device Clear on the bus), not the 0x03 byte.
//! - **No `SYST:REM`**: [`Transport::needs_remote_command`] is false (REN does it on GPIB; the
//!   34401A's `SYST:REM`/`SYST:LOC` are RS-232-only).
//! - **`write_raw`**: a GPIB write is a message. The bytes are escaped and followed by an
//!   unescaped LF, which makes the controller send them (plus its `++eos` LF and EOI).

use std::time::Duration;

use tokio::time::Instant;

use crate::port::PrologixOptions;
use crate::{Field, LinkError, Transport};

/// The escape character of the Prologix protocol.
pub const ESC: u8 = 0x1b;

impl PrologixOptions {
    /// The commands sent at open, in order (without their LF).
    pub fn setup_commands(&self) -> Vec<String> {
        vec![
            "++savecfg 0".into(),
            "++mode 1".into(),
            "++ifc".into(),
            format!("++addr {}", self.addr),
            "++auto 0".into(),
            "++eoi 1".into(),
            "++eos 2".into(),
            "++eot_enable 0".into(),
            format!("++read_tmo_ms {}", self.read_tmo.as_millis()),
        ]
    }
}

/// Escapes `data` for the controller: ESC before CR, LF, ESC and `+`.
pub fn escape(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(data.len() + 4);
    for &b in data {
        if matches!(b, b'\r' | b'\n' | ESC | b'+') {
            out.push(ESC);
        }
        out.push(b);
    }
    out
}

/// An instrument on GPIB behind a Prologix controller reached through `inner` (see the module
/// documentation for the protocol and its reasons).
#[derive(Debug)]
pub struct PrologixTransport<T> {
    inner: T,
    name: String,
    options: PrologixOptions,
    version: String,
    /// A `++read eoi` was sent and its reply has not ended yet.
    armed: bool,
}

impl<T: Transport> PrologixTransport<T> {
    /// Sets the controller up over `inner` (see the module documentation) and checks that it
    /// answers `++ver`. `inner` carries the controller's byte stream (a serial port or a TCP
    /// connection to port 1234).
    pub async fn open(inner: T, options: PrologixOptions) -> Result<Self, LinkError> {
        let name = format!("{} (GPIB {})", inner.describe(), options.addr);
        if let Err(e) = options.validate() {
            return Err(LinkError::io(
                name,
                "configuring the Prologix controller",
                std::io::Error::new(std::io::ErrorKind::InvalidInput, e),
            ));
        }
        let mut t = PrologixTransport {
            inner,
            name,
            options,
            version: String::new(),
            armed: false,
        };
        t.inner.discard_input().await?;
        for cmd in t.options.setup_commands() {
            t.controller(&cmd).await?;
        }
        t.controller("++ver").await?;
        let version = t.inner.read_line(Some(t.options.open_timeout)).await?;
        tracing::debug!(link = %t.name, version = %version, "Prologix controller set up");
        t.version = version;
        Ok(t)
    }

    /// What the controller answered to `++ver`.
    pub fn version(&self) -> &str {
        &self.version
    }

    /// The options the controller was set up with.
    pub fn options(&self) -> &PrologixOptions {
        &self.options
    }

    /// The link to the controller.
    pub fn get_ref(&self) -> &T {
        &self.inner
    }

    /// The link to the controller, mutably.
    pub fn get_mut(&mut self) -> &mut T {
        &mut self.inner
    }

    /// The link to the controller back.
    pub fn into_inner(self) -> T {
        self.inner
    }

    /// Sends a controller command (`++...`), unescaped, with its LF.
    pub async fn controller(&mut self, cmd: &str) -> Result<(), LinkError> {
        let mut bytes = Vec::with_capacity(cmd.len() + 1);
        bytes.extend_from_slice(cmd.as_bytes());
        bytes.push(b'\n');
        self.inner.write_raw(&bytes).await
    }

    /// Sends data to the instrument: escaped, then the LF that makes the controller send it.
    async fn data(&mut self, data: &[u8]) -> Result<(), LinkError> {
        // a new message ends whatever read was outstanding
        self.armed = false;
        let mut bytes = escape(data);
        bytes.push(b'\n');
        self.inner.write_raw(&bytes).await
    }

    /// Reads with `take` (a line or a field from the inner link), sending `++read eoi` when no
    /// read is outstanding and again after a silence longer than the controller's read timeout.
    async fn read_with<R: Send>(
        &mut self,
        timeout: Option<Duration>,
        mut take: impl AsyncTake<T, R> + Send,
    ) -> Result<(R, bool), LinkError> {
        let deadline = timeout.map(|t| Instant::now() + t);
        let slice = self.options.read_tmo + self.options.rearm_margin;
        let mut seen = 0usize;
        loop {
            if !self.armed {
                self.controller("++read eoi").await?;
                self.armed = true;
            }
            let now = Instant::now();
            // the last slice waits until the caller's deadline
            let (wait, last) = match deadline {
                Some(d) => {
                    let left = d.saturating_duration_since(now);
                    (left.min(slice), left <= slice)
                }
                None => (slice, false),
            };
            match take.take(&mut self.inner, wait).await {
                Ok((item, end_of_line)) => {
                    if end_of_line {
                        self.armed = false;
                    }
                    return Ok((item, end_of_line));
                }
                Err(LinkError::Timeout {
                    device, partial, ..
                }) if last => {
                    return Err(LinkError::Timeout {
                        device,
                        timeout: timeout.unwrap_or_default(),
                        partial,
                    });
                }
                Err(LinkError::Timeout { partial, .. }) => {
                    if partial.len() == seen {
                        // silence for longer than the controller's read timeout: it gave up
                        self.armed = false;
                    }
                    seen = partial.len();
                }
                Err(e) => {
                    self.armed = false;
                    return Err(e);
                }
            }
        }
    }
}

/// One read from the inner link with a timeout; the `bool` says whether the reply's line
/// ended. A small trait instead of a closure returning a future borrowing the link.
trait AsyncTake<T, R> {
    fn take(
        &mut self,
        inner: &mut T,
        timeout: Duration,
    ) -> impl Future<Output = Result<(R, bool), LinkError>> + Send;
}

struct TakeLine;
impl<T: Transport> AsyncTake<T, String> for TakeLine {
    async fn take(
        &mut self,
        inner: &mut T,
        timeout: Duration,
    ) -> Result<(String, bool), LinkError> {
        Ok((inner.read_line(Some(timeout)).await?, true))
    }
}

struct TakeField(u8);
impl<T: Transport> AsyncTake<T, Field> for TakeField {
    async fn take(&mut self, inner: &mut T, timeout: Duration) -> Result<(Field, bool), LinkError> {
        let f = inner.read_field(self.0, Some(timeout)).await?;
        let eol = f.end_of_line;
        Ok((f, eol))
    }
}

impl<T: Transport> Transport for PrologixTransport<T> {
    fn describe(&self) -> &str {
        &self.name
    }

    /// Escapes `bytes` and ends them with the LF that makes the controller send them to the
    /// instrument (a GPIB write is a message; the controller adds its `++eos` LF and EOI).
    async fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.data(bytes).await
    }

    async fn send_line(&mut self, line: &str) -> Result<(), LinkError> {
        self.data(line.as_bytes()).await
    }

    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        Ok(self.read_with(timeout, TakeLine).await?.0)
    }

    async fn read_field(&mut self, sep: u8, timeout: Option<Duration>) -> Result<Field, LinkError> {
        Ok(self.read_with(timeout, TakeField(sep)).await?.0)
    }

    /// Throws away what the controller sent and not yet read, and forgets the outstanding read
    /// (the next read asks again).
    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        self.armed = false;
        self.inner.discard_input().await
    }

    /// `++clr` (Selected Device Clear to the instrument's address), then the input discarded.
    async fn device_clear(&mut self) -> Result<(), LinkError> {
        self.armed = false;
        self.controller("++clr").await?;
        self.inner.discard_input().await?;
        Ok(())
    }

    fn needs_remote_command(&self) -> bool {
        false
    }

    /// `++loc`: the controller releases REN for the instrument, which goes to local.
    async fn return_to_local(&mut self) -> Result<(), LinkError> {
        self.armed = false;
        self.controller("++loc").await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ErrorKind, ScriptedTransport};

    fn opened(script: ScriptedTransport) -> ScriptedTransport {
        script
            .expect_line("++savecfg 0")
            .expect_line("++mode 1")
            .expect_line("++ifc")
            .expect_line("++addr 22")
            .expect_line("++auto 0")
            .expect_line("++eoi 1")
            .expect_line("++eos 2")
            .expect_line("++eot_enable 0")
            .expect_line("++read_tmo_ms 1000")
            .query("++ver", "Prologix GPIB-USB Controller version 6.107")
    }

    #[tokio::test]
    async fn open_query_clear_and_escaping_bytes() {
        let script = opened(ScriptedTransport::new("prologix"))
            .expect_line("*IDN?")
            .query("++read eoi", "HEWLETT-PACKARD,34401A,0,11-5-2")
            .expect_line("*RST;*CLS")
            .expect_line("++clr")
            // CR, LF, ESC and + escaped; the unescaped LF ends the message
            .expect_raw(b"DISP:TEXT \"\x1b+1\x1b\r\x1b\n\x1b\x1b\"\n")
            .expect_raw(b"\x03\n");
        let mut t = PrologixTransport::open(script, PrologixOptions::default())
            .await
            .unwrap();
        assert_eq!(t.version(), "Prologix GPIB-USB Controller version 6.107");
        assert!(!t.needs_remote_command());
        assert_eq!(t.describe(), "prologix (GPIB 22)");
        t.send_line("*IDN?").await.unwrap();
        assert_eq!(
            t.read_line(Some(Duration::from_secs(1))).await.unwrap(),
            "HEWLETT-PACKARD,34401A,0,11-5-2"
        );
        t.send_line("*RST;*CLS").await.unwrap();
        t.device_clear().await.unwrap();
        t.send_line("DISP:TEXT \"+1\r\n\x1b\"").await.unwrap();
        t.write_raw(&[0x03]).await.unwrap();
        t.into_inner().done();
    }

    #[tokio::test]
    async fn one_read_per_reply_fields_included_and_rearm_after_silence() {
        let script = opened(ScriptedTransport::new("prologix"))
            .expect_line("READ?")
            .query("++read eoi", "+1.0E+00,+2.0E+00")
            // a long wait: the controller gave up, the transport asks again
            .expect_line("INIT;*OPC?")
            .expect_line("++read eoi")
            .silence()
            .query("++read eoi", "1");
        let mut t = PrologixTransport::open(script, PrologixOptions::default())
            .await
            .unwrap();
        t.send_line("READ?").await.unwrap();
        let s = Some(Duration::from_secs(1));
        let f = t.read_field(b',', s).await.unwrap();
        assert_eq!((f.text.as_str(), f.end_of_line), ("+1.0E+00", false));
        let f = t.read_field(b',', s).await.unwrap();
        assert_eq!((f.text.as_str(), f.end_of_line), ("+2.0E+00", true));
        t.send_line("INIT;*OPC?").await.unwrap();
        assert_eq!(
            t.read_line(Some(Duration::from_secs(60))).await.unwrap(),
            "1"
        );
        t.into_inner().done();
    }

    #[tokio::test]
    async fn timeout_is_reported_with_the_callers_timeout() {
        let script = opened(ScriptedTransport::new("prologix"))
            .expect_line("*IDN?")
            .expect_line("++read eoi")
            .silence();
        let mut t = PrologixTransport::open(script, PrologixOptions::default())
            .await
            .unwrap();
        t.send_line("*IDN?").await.unwrap();
        // shorter than one re-arm slice: one read, one timeout
        let err = t
            .read_line(Some(Duration::from_millis(500)))
            .await
            .unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Timeout);
        assert!(err.to_string().contains("500ms"), "{err}");
        t.into_inner().done();
    }

    #[tokio::test]
    async fn bad_options_are_refused_before_anything_is_sent() {
        let opts = PrologixOptions {
            addr: 31,
            ..PrologixOptions::default()
        };
        let err = PrologixTransport::open(ScriptedTransport::new("p"), opts)
            .await
            .unwrap_err();
        assert!(err.to_string().contains("GPIB address 31"), "{err}");
    }

    #[test]
    fn escape_marks_cr_lf_esc_and_plus() {
        assert_eq!(escape(b"a+\r\n\x1bz"), b"a\x1b+\x1b\r\x1b\n\x1b\x1bz");
    }
}
