//! Where an instrument is connected: a port string parsed once into [`PortSpec`], with no I/O
//! (built without the `io` feature, so the synchronous plan crate parses a plan's
//! `port = "..."` into this very type and nothing downstream parses the string again).
//!
//! Port strings:
//! - `tcp://HOST:PORT` (IPv6 as `tcp://[::1]:9878`): an RS-232 instrument behind a
//!   serial-to-Ethernet converter, a table controller's TCP port, or a LAN meter's SCPI socket;
//! - `prologix:<serial path>[?addr=N&read_tmo_ms=T]`: an instrument on GPIB behind a Prologix
//!   GPIB-USB controller (a USB serial port), e.g. `prologix:/dev/ttyUSB0?addr=22`;
//! - `prologix-tcp://HOST[:PORT][?addr=N&read_tmo_ms=T]`: behind a Prologix GPIB-ETHERNET
//!   controller (port 1234 when none is given), e.g. `prologix-tcp://10.0.0.7:1234?addr=22`;
//! - anything else without `://`: a serial port path (`/dev/ttyUSB0`, `COM3`, a
//!   pseudo-terminal's path).
//!
//! `addr` is the instrument's primary GPIB address, 0–30, default 22 (the 34401A's factory
//! address); `read_tmo_ms` the controller's `++read_tmo_ms`, 1–3000, default 1000.
//!
//! The model is probe-rs's `DebugProbeSelector`: serde reads the type straight from text
//! (`try_from = "String"`) and writes it back as text, so a configuration holds the parsed
//! port, never the string. A port displays in its canonical form, which parses back to the
//! same value (a GPIB port with its address spelled out).

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// The scheme prefix that selects TCP (an instrument behind a serial-to-Ethernet converter).
pub const TCP_SCHEME: &str = "tcp://";
/// The prefix that selects a Prologix GPIB-USB controller on a serial port.
pub const PROLOGIX_SCHEME: &str = "prologix:";
/// The prefix that selects a Prologix GPIB-ETHERNET controller.
pub const PROLOGIX_TCP_SCHEME: &str = "prologix-tcp://";
/// The TCP port of the Prologix GPIB-ETHERNET controller.
pub const PROLOGIX_TCP_PORT: u16 = 1234;
/// The HP 34401A's factory GPIB address, the default `addr`.
pub const DEFAULT_GPIB_ADDRESS: u8 = 22;
/// The controller's default `++read_tmo_ms`.
const DEFAULT_READ_TMO: Duration = Duration::from_millis(1000);

/// How a Prologix controller is set up (`PrologixTransport::open` with the `io` feature).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PrologixOptions {
    /// The instrument's primary GPIB address, 0–30. Default 22 (the 34401A's factory address).
    pub addr: u8,
    /// `++read_tmo_ms`: how long the controller waits for each character of a reply, 1–3000 ms.
    /// Default 1000 ms.
    pub read_tmo: Duration,
    /// Extra silence, beyond `read_tmo`, before an outstanding read is sent again (the
    /// controller has given up by then). Default 200 ms.
    pub rearm_margin: Duration,
    /// How long the controller may take to answer `++ver` at open. Default 2 s.
    pub open_timeout: Duration,
}

impl Default for PrologixOptions {
    fn default() -> Self {
        PrologixOptions {
            addr: DEFAULT_GPIB_ADDRESS,
            read_tmo: DEFAULT_READ_TMO,
            rearm_margin: Duration::from_millis(200),
            open_timeout: Duration::from_secs(2),
        }
    }
}

impl PrologixOptions {
    /// Checks the address (0–30) and the read timeout (1–3000 ms).
    pub fn validate(&self) -> Result<(), String> {
        if self.addr > 30 {
            return Err(format!("GPIB address {} out of range 0..=30", self.addr));
        }
        let ms = self.read_tmo.as_millis();
        if !(1..=3000).contains(&ms) {
            return Err(format!("read_tmo_ms {ms} out of range 1..=3000"));
        }
        Ok(())
    }
}

/// What a port string names (see the module documentation), parsed without opening anything.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum PortSpec {
    /// A serial device (`/dev/ttyUSB0`, `COM3`, a pseudo-terminal).
    Serial(PathBuf),
    /// A TCP endpoint (`tcp://HOST:PORT`), e.g. a serial-to-Ethernet converter, ACL's port
    /// 9878, or a LAN meter's SCPI socket (5025).
    Tcp {
        /// Host name or address (IPv6 without brackets).
        host: String,
        /// TCP port (1..=65535).
        port: u16,
    },
    /// A Prologix GPIB-USB controller on the serial port at `path`.
    PrologixSerial {
        /// The controller's serial port.
        path: PathBuf,
        /// Address and read timeout.
        options: PrologixOptions,
    },
    /// A Prologix GPIB-ETHERNET controller at `host:port`.
    PrologixTcp {
        /// Host name or address (IPv6 without brackets).
        host: String,
        /// TCP port (1234 when the string had none).
        port: u16,
        /// Address and read timeout.
        options: PrologixOptions,
    },
}

/// What kind of mistake a port string has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PortErrorKind {
    /// Empty, or only blanks.
    Empty,
    /// A control character (a pasted newline, a tab).
    ControlCharacter,
    /// `xyz://` that is none of the schemes.
    UnknownScheme,
    /// A `tcp://` string that is not `tcp://HOST:PORT`.
    Tcp,
    /// A `prologix:` or `prologix-tcp://` string with a wrong part.
    Gpib,
}

/// A port string that is not one (see the module documentation); the message names the part
/// that is wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortError {
    kind: PortErrorKind,
    message: String,
}

impl PortError {
    fn new(kind: PortErrorKind, message: String) -> PortError {
        PortError { kind, message }
    }

    /// What kind of mistake it is.
    pub fn kind(&self) -> PortErrorKind {
        self.kind
    }
}

impl fmt::Display for PortError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for PortError {}

fn gpib(message: String) -> PortError {
    PortError::new(PortErrorKind::Gpib, message)
}

/// Parses the `?addr=N&read_tmo_ms=T` part of a Prologix port string.
fn prologix_query(query: Option<&str>) -> Result<PrologixOptions, PortError> {
    let mut options = PrologixOptions::default();
    let Some(query) = query else {
        return Ok(options);
    };
    for pair in query.split('&') {
        let Some((key, value)) = pair.split_once('=') else {
            return Err(gpib(format!(
                "parameter {pair:?} is not key=value (use addr=N, read_tmo_ms=T)"
            )));
        };
        match key {
            "addr" => {
                options.addr = value
                    .parse::<u8>()
                    .ok()
                    .filter(|a| *a <= 30)
                    .ok_or_else(|| {
                        gpib(format!(
                            "addr {value:?} is not a GPIB primary address (0..=30)"
                        ))
                    })?;
            }
            "read_tmo_ms" => {
                let ms = value
                    .parse::<u64>()
                    .ok()
                    .filter(|m| (1..=3000).contains(m))
                    .ok_or_else(|| {
                        gpib(format!(
                            "read_tmo_ms {value:?} is not a number of ms in 1..=3000"
                        ))
                    })?;
                options.read_tmo = Duration::from_millis(ms);
            }
            other => {
                return Err(gpib(format!(
                    "unknown parameter {other:?} (use addr=N, read_tmo_ms=T)"
                )));
            }
        }
    }
    Ok(options)
}

/// `HOST:PORT` or `[V6]:PORT` (`default_port` when `PORT` is left out and one is allowed):
/// the host without brackets and the port, or `None` when the text is not that.
fn host_port(text: &str, default_port: Option<u16>) -> Option<(String, u16)> {
    let (host, port) = if let Some(v6) = text.strip_prefix('[') {
        let (host, after) = v6.split_once(']')?;
        match after.strip_prefix(':') {
            Some(p) => (host, Some(p)),
            None if after.is_empty() => (host, None),
            None => return None,
        }
    } else {
        match text.rsplit_once(':') {
            Some((h, p)) => (h, Some(p)),
            None => (text, None),
        }
    };
    if host.is_empty() || host.contains(['/', ' ', '[', ']']) {
        return None;
    }
    if host.contains(':') && !text.starts_with('[') {
        return None;
    }
    let port = match port {
        Some(p) => p.parse::<u16>().ok().filter(|p| *p != 0)?,
        None => default_port?,
    };
    Some((host.to_string(), port))
}

/// `host:port`, bracketing an IPv6 host.
fn join_host_port(host: &str, port: u16) -> String {
    if host.contains(':') {
        format!("[{host}]:{port}")
    } else {
        format!("{host}:{port}")
    }
}

impl PortSpec {
    /// Parses a port string (see the module documentation). The error names the part that is
    /// wrong.
    pub fn parse(s: &str) -> Result<PortSpec, PortError> {
        if s.trim().is_empty() {
            return Err(PortError::new(
                PortErrorKind::Empty,
                "must not be empty (an empty port string names no device)".into(),
            ));
        }
        if s.chars().any(char::is_control) {
            return Err(PortError::new(
                PortErrorKind::ControlCharacter,
                format!("must not contain control characters (got {s:?})"),
            ));
        }
        if let Some(rest) = s.strip_prefix(PROLOGIX_TCP_SCHEME) {
            let (host, query) = match rest.split_once('?') {
                Some((h, q)) => (h, Some(q)),
                None => (rest, None),
            };
            if host.is_empty() {
                return Err(gpib(
                    "no host (expected prologix-tcp://host[:port][?addr=N])".into(),
                ));
            }
            if host.starts_with(':') {
                return Err(gpib("no host before the port".into()));
            }
            let Some((host, port)) = host_port(host, Some(PROLOGIX_TCP_PORT)) else {
                let port = host.rsplit_once(':').map_or(host, |(_, p)| p);
                return Err(gpib(format!(
                    "port {port:?} is not a TCP port (expected prologix-tcp://host[:port][?addr=N], \
                     IPv6 in brackets)"
                )));
            };
            let options = prologix_query(query)?;
            return Ok(PortSpec::PrologixTcp {
                host,
                port,
                options,
            });
        }
        if let Some(rest) = s.strip_prefix(PROLOGIX_SCHEME) {
            let (path, query) = match rest.split_once('?') {
                Some((p, q)) => (p, Some(q)),
                None => (rest, None),
            };
            if path.is_empty() {
                return Err(gpib(
                    "no serial port (expected prologix:/dev/ttyUSB0[?addr=N])".into(),
                ));
            }
            let options = prologix_query(query)?;
            return Ok(PortSpec::PrologixSerial {
                path: PathBuf::from(path),
                options,
            });
        }
        if let Some(rest) = s.strip_prefix(TCP_SCHEME) {
            let (host, port) = host_port(rest, None).ok_or_else(|| {
                PortError::new(
                    PortErrorKind::Tcp,
                    format!("must be tcp://HOST:PORT with PORT in 1..=65535 (got {s:?})"),
                )
            })?;
            return Ok(PortSpec::Tcp { host, port });
        }
        if s.contains("://") {
            return Err(PortError::new(
                PortErrorKind::UnknownScheme,
                format!(
                    "unknown scheme: use a device path, tcp://HOST:PORT, prologix:DEVICE?addr=N or \
                     prologix-tcp://HOST?addr=N (got {s:?})"
                ),
            ));
        }
        Ok(PortSpec::Serial(PathBuf::from(s)))
    }

    /// True for an instrument on GPIB behind a Prologix controller (the 34401A then takes no
    /// `SYST:REM`, its baud rate does not apply, device clear is `++clr`).
    pub fn is_gpib(&self) -> bool {
        matches!(
            self,
            PortSpec::PrologixSerial { .. } | PortSpec::PrologixTcp { .. }
        )
    }

    /// True for a `tcp://` endpoint (a converter, a controller's port or a LAN meter's socket).
    pub fn is_tcp(&self) -> bool {
        matches!(self, PortSpec::Tcp { .. })
    }

    /// The Prologix controller's settings, for a GPIB port.
    pub fn prologix_options(&self) -> Option<&PrologixOptions> {
        match self {
            PortSpec::PrologixSerial { options, .. } | PortSpec::PrologixTcp { options, .. } => {
                Some(options)
            }
            PortSpec::Serial(_) | PortSpec::Tcp { .. } => None,
        }
    }

    /// `host:port` of a TCP endpoint or a GPIB-ETHERNET controller (IPv6 in brackets), as a
    /// socket connects to it.
    pub fn socket_address(&self) -> Option<String> {
        match self {
            PortSpec::Tcp { host, port } | PortSpec::PrologixTcp { host, port, .. } => {
                Some(join_host_port(host, *port))
            }
            PortSpec::Serial(_) | PortSpec::PrologixSerial { .. } => None,
        }
    }
}

impl fmt::Display for PortSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let query = |f: &mut fmt::Formatter<'_>, o: &PrologixOptions| {
            write!(f, "?addr={}", o.addr)?;
            if o.read_tmo != DEFAULT_READ_TMO {
                write!(f, "&read_tmo_ms={}", o.read_tmo.as_millis())?;
            }
            Ok(())
        };
        match self {
            PortSpec::Serial(p) => write!(f, "{}", p.display()),
            PortSpec::Tcp { host, port } => {
                write!(f, "{TCP_SCHEME}{}", join_host_port(host, *port))
            }
            PortSpec::PrologixSerial { path, options } => {
                write!(f, "{PROLOGIX_SCHEME}{}", path.display())?;
                query(f, options)
            }
            PortSpec::PrologixTcp {
                host,
                port,
                options,
            } => {
                write!(f, "{PROLOGIX_TCP_SCHEME}{}", join_host_port(host, *port))?;
                query(f, options)
            }
        }
    }
}

impl std::str::FromStr for PortSpec {
    type Err = PortError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        PortSpec::parse(s)
    }
}

impl TryFrom<String> for PortSpec {
    type Error = PortError;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        PortSpec::parse(&s)
    }
}

impl From<PortSpec> for String {
    fn from(p: PortSpec) -> String {
        p.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_canonical_form_parses_back_to_the_same_port() {
        for s in [
            "/dev/ttyUSB0",
            "COM3",
            "tcp://10.0.0.5:4001",
            "tcp://[::1]:9878",
            "prologix:/dev/ttyUSB0",
            "prologix:/dev/ttyUSB0?read_tmo_ms=3000&addr=5",
            "prologix-tcp://10.0.0.7",
            "prologix-tcp://[::1]?addr=0",
        ] {
            let p = PortSpec::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"));
            let shown = p.to_string();
            assert_eq!(PortSpec::parse(&shown), Ok(p.clone()), "{s} -> {shown}");
        }
        assert_eq!(
            PortSpec::parse("prologix-tcp://10.0.0.7")
                .map(|p| p.to_string())
                .as_deref(),
            Ok("prologix-tcp://10.0.0.7:1234?addr=22")
        );
    }

    #[test]
    fn serde_reads_a_port_from_text_and_writes_it_back() {
        #[derive(Debug, PartialEq, Deserialize, Serialize)]
        struct Doc {
            port: PortSpec,
        }
        let doc: Doc = serde_json::from_str(r#"{"port":"prologix:COM4?addr=9"}"#)
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(doc.port.is_gpib());
        assert_eq!(doc.port.prologix_options().map(|o| o.addr), Some(9));
        assert_eq!(
            serde_json::to_string(&doc).ok().as_deref(),
            Some(r#"{"port":"prologix:COM4?addr=9"}"#)
        );
        assert!(
            serde_json::from_str::<Doc>(r#"{"port":"tcp://host"}"#).is_err(),
            "tcp://host must be refused"
        );
    }

    #[test]
    fn properties_are_the_parsed_ports() {
        let p = |s: &str| PortSpec::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"));
        assert!(p("prologix-tcp://h?addr=3").is_gpib());
        assert!(!p("tcp://h:5025").is_gpib());
        assert!(p("tcp://h:5025").is_tcp());
        assert!(!p("/dev/ttyUSB0").is_tcp());
        assert_eq!(
            p("tcp://[::1]:5025").socket_address().as_deref(),
            Some("[::1]:5025")
        );
        assert_eq!(
            PortSpec::parse("tcp://host").map_err(|e| e.kind()),
            Err(PortErrorKind::Tcp)
        );
        assert_eq!(
            PortSpec::parse("prologix:x?addr=99").map_err(|e| e.kind()),
            Err(PortErrorKind::Gpib)
        );
    }
}
