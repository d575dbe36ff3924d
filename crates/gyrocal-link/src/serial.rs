//! Serial ports (real RS-232 adapters and pseudo-terminals) through `tokio-serial`.
//!
//! The HP 34401A and most rate-table controllers of its era speak 300–9600 baud with two stop
//! bits, and with parity and data bits tied together (None/8, Even/7, Odd/7). The meter will not
//! transmit while the host's DTR is false, and `serialport` has no DTR/DSR flow control, so the
//! port is opened without flow control and DTR is asserted by hand. Pseudo-terminals (used by the
//! simulator) have no modem lines: the `ENOTTY` that asserting DTR gives there is logged, not
//! fatal. Whatever the previous user of the port left in its input buffer is thrown away after
//! opening, so the first reply the driver reads is an answer to its own first question.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use tokio_serial::{
    ClearBuffer, DataBits, FlowControl, Parity, SerialPort, SerialStream, StopBits,
};

use crate::{Framing, LinkError, SUPPORTED_BAUDS, StreamTransport};

/// The serial settings of a framing.
fn settings(framing: Framing) -> (DataBits, Parity) {
    match framing {
        Framing::EightNone => (DataBits::Eight, Parity::None),
        Framing::SevenEven => (DataBits::Seven, Parity::Even),
        Framing::SevenOdd => (DataBits::Seven, Parity::Odd),
    }
}

/// How to open a link. Serial settings are ignored for TCP.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LinkOptions {
    /// Baud rate, one of [`SUPPORTED_BAUDS`]. Default 9600 (the 34401A's factory setting).
    pub baud: u32,
    /// Character framing. Default 8N2.
    pub framing: Framing,
    /// How long a TCP connection may take to establish. Default 5 s.
    #[serde(with = "secs")]
    pub connect_timeout: Duration,
    /// A `tcp://` port is a LAN instrument's raw SCPI socket (port 5025 of a Keysight
    /// Truevolt), not an RS-232 instrument behind a serial-to-Ethernet converter: [`crate::open`]
    /// then returns a [`crate::SocketTransport`], whose device clear reconnects instead of
    /// sending the RS-232 Ctrl-C byte. Default false (a converter: the byte passes through).
    #[serde(default)]
    pub scpi_socket: bool,
}

impl Default for LinkOptions {
    fn default() -> Self {
        LinkOptions {
            baud: 9600,
            framing: Framing::EightNone,
            connect_timeout: Duration::from_secs(5),
            scpi_socket: false,
        }
    }
}

impl LinkOptions {
    /// Checks the serial settings before anything is opened.
    pub fn validate(&self, device: &str) -> Result<(), LinkError> {
        if !SUPPORTED_BAUDS.contains(&self.baud) {
            return Err(LinkError::io(
                device,
                "configuring",
                std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!(
                        "baud {} not supported (use one of {SUPPORTED_BAUDS:?})",
                        self.baud
                    ),
                ),
            ));
        }
        Ok(())
    }

    /// Time one character takes on the wire at this baud (11 bits).
    pub fn char_time(&self) -> Duration {
        Duration::from_secs_f64(f64::from(Framing::BITS_PER_CHAR) / f64::from(self.baud.max(1)))
    }
}

mod secs {
    use serde::{Deserialize, Deserializer, Serializer};
    use std::time::Duration;

    pub fn serialize<S: Serializer>(d: &Duration, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(d.as_secs_f64())
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        let v = f64::deserialize(d)?;
        Duration::try_from_secs_f64(v).map_err(serde::de::Error::custom)
    }
}

fn serial_err(path: &str, context: &str, e: tokio_serial::Error) -> LinkError {
    LinkError::io(path, context, std::io::Error::from(e))
}

/// Opens a serial port (or the slave side of a pseudo-terminal) with `options`: no flow control,
/// DTR asserted (failures tolerated and logged), stale input cleared.
pub fn open_serial(
    path: &str,
    options: &LinkOptions,
) -> Result<StreamTransport<SerialStream>, LinkError> {
    options.validate(path)?;
    let (data_bits, parity) = settings(options.framing);
    let builder = tokio_serial::new(path, options.baud)
        .data_bits(data_bits)
        .parity(parity)
        .stop_bits(StopBits::Two)
        .flow_control(FlowControl::None);
    let mut port = SerialStream::open(&builder).map_err(|e| match not_a_terminal(path) {
        Some(what) => LinkError::io(
            path,
            "opening",
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "{path} is not a serial port (not a terminal device: it is {what}); set the \
                     port to the serial adapter's device (e.g. /dev/ttyUSB0) or to \
                     tcp://HOST:PORT"
                ),
            ),
        ),
        None => serial_err(path, "opening", e),
    })?;
    prepare(&mut port, path);
    tracing::debug!(port = path, baud = options.baud, framing = %options.framing, "serial port open");
    Ok(StreamTransport::new(port, path))
}

/// What `path` is when it plainly cannot be a serial port (a regular file, a directory, a pipe,
/// a socket, or a character device that is not a terminal such as `/dev/null`); `None` when it
/// is a terminal, does not exist or cannot be looked at (the open error then speaks for itself).
/// Called only after opening it as a serial port failed.
#[cfg(unix)]
fn not_a_terminal(path: &str) -> Option<&'static str> {
    use std::io::IsTerminal as _;
    use std::os::unix::fs::{FileTypeExt as _, OpenOptionsExt as _};
    let kind = std::fs::metadata(path).ok()?.file_type();
    if kind.is_file() {
        Some("a regular file")
    } else if kind.is_dir() {
        Some("a directory")
    } else if kind.is_fifo() {
        Some("a pipe")
    } else if kind.is_socket() {
        Some("a socket")
    } else if kind.is_block_device() {
        Some("a block device")
    } else if kind.is_char_device() {
        // Non-blocking and without becoming the controlling terminal: a real port that is busy
        // or has no carrier must not hang this check.
        let file = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
            .open(path)
            .ok()?;
        (!file.is_terminal()).then_some("a device that is not a terminal")
    } else {
        None
    }
}

#[cfg(not(unix))]
fn not_a_terminal(_path: &str) -> Option<&'static str> {
    None
}

/// Asserts DTR and RTS and clears stale input; on ports without modem lines (pseudo-terminals,
/// some adapters) the failures are logged and ignored.
fn prepare(port: &mut SerialStream, path: &str) {
    if let Err(e) = port.write_data_terminal_ready(true) {
        tracing::info!(port = path, error = %e, "cannot assert DTR (no modem lines?); continuing");
    }
    if let Err(e) = port.write_request_to_send(true) {
        tracing::debug!(port = path, error = %e, "cannot assert RTS; continuing");
    }
    if let Err(e) = port.clear(ClearBuffer::Input) {
        tracing::info!(port = path, error = %e, "cannot clear stale input; continuing");
    }
}

/// A pseudo-terminal pair for tests and simulated benches (Unix only).
///
/// Returns `(device, placeholder, path)`: `device` is the master side a simulator serves,
/// `path` is the slave side's path, to be opened through [`open_serial`] (or [`crate::open`]) like
/// a real port. `placeholder` is the slave as `openpty` left it open: keep it until the host side
/// has opened `path` (a pseudo-terminal with no slave open reports hang-ups to the master), then
/// drop it. Keep `device` alive until the host is done.
#[cfg(unix)]
pub fn pseudo_terminal() -> Result<(SerialStream, SerialStream, String), LinkError> {
    let (master, slave) =
        SerialStream::pair().map_err(|e| serial_err("pseudo-terminal", "creating", e))?;
    let path = slave.name().ok_or_else(|| {
        LinkError::io(
            "pseudo-terminal",
            "naming",
            std::io::Error::other("the slave side has no path"),
        )
    })?;
    Ok((master, slave, path))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    /// A regular file, `/dev/null` or a directory named as a port is said not to be a serial
    /// port, naming it, instead of the bare `ENOTTY` ("Not a typewriter").
    #[tokio::test]
    async fn a_port_that_is_not_a_terminal_says_so() {
        let dir = std::env::temp_dir().join(format!("gyrocal-link-notty-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let file = dir.join("plan.toml");
        std::fs::write(&file, "not a port\n").unwrap_or_else(|e| panic!("{e}"));
        let file = file.to_string_lossy().into_owned();
        let dir_s = dir.to_string_lossy().into_owned();
        for (path, what) in [
            (file.as_str(), "a regular file"),
            ("/dev/null", "a device that is not a terminal"),
            (dir_s.as_str(), "a directory"),
        ] {
            let Err(err) = open_serial(path, &LinkOptions::default()) else {
                panic!("{path} opened as a serial port");
            };
            let text = err.to_string();
            assert!(
                text.contains(&format!(
                    "{path} is not a serial port (not a terminal device: it is {what})"
                )),
                "{text}"
            );
            assert!(!text.contains("typewriter"), "{text}");
            assert_eq!(err.kind(), crate::ErrorKind::Io);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A pseudo-terminal (no modem lines: asserting DTR gives ENOTTY) still opens.
    #[tokio::test]
    async fn a_pseudo_terminal_still_opens() {
        let (_master, placeholder, path) = pseudo_terminal().unwrap_or_else(|e| panic!("{e}"));
        let opened = open_serial(&path, &LinkOptions::default());
        drop(placeholder);
        assert!(opened.is_ok(), "{:?}", opened.err().map(|e| e.to_string()));
    }
}
