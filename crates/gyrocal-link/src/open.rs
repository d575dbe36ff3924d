//! [`open`]: one entry point that turns a port string into a transport.
//!
//! Port strings:
//! - `tcp://host:port`: an RS-232 instrument behind a serial-to-Ethernet converter;
//! - `prologix:<serial path>[?addr=N&read_tmo_ms=T]`: an instrument on GPIB behind a Prologix
//!   GPIB-USB controller (a USB serial port), e.g. `prologix:/dev/ttyUSB0?addr=22`;
//! - `prologix-tcp://host[:port][?addr=N&read_tmo_ms=T]`: behind a Prologix GPIB-ETHERNET
//!   controller (port 1234 when none is given), e.g. `prologix-tcp://10.0.0.7:1234?addr=22`;
//! - anything else: a serial port path (`/dev/ttyUSB0`, `COM3`, a pseudo-terminal's path).
//!
//! `addr` is the instrument's primary GPIB address, 0–30, default 22 (the 34401A's factory
//! address); `read_tmo_ms` the controller's `++read_tmo_ms`, 1–3000, default 1000.

use std::time::Duration;

use tokio::net::TcpStream;

use crate::prologix::{PROLOGIX_TCP_PORT, PrologixOptions, PrologixTransport};
use crate::{
    DynStream, Field, LinkError, LinkOptions, SocketTransport, StreamTransport, Transport,
    open_serial, tcp_connector,
};

/// The scheme prefix that selects TCP (an instrument behind a serial-to-Ethernet converter).
pub const TCP_SCHEME: &str = "tcp://";
/// The prefix that selects a Prologix GPIB-USB controller on a serial port.
pub const PROLOGIX_SCHEME: &str = "prologix:";
/// The prefix that selects a Prologix GPIB-ETHERNET controller.
pub const PROLOGIX_TCP_SCHEME: &str = "prologix-tcp://";

/// Connects to `tcp://host:port` (the scheme is optional here).
pub async fn open_tcp(
    spec: &str,
    timeout: Duration,
) -> Result<StreamTransport<TcpStream>, LinkError> {
    let addr = spec.strip_prefix(TCP_SCHEME).unwrap_or(spec);
    let name = format!("{TCP_SCHEME}{addr}");
    if addr.is_empty() || !addr.contains(':') {
        return Err(LinkError::io(
            &name,
            "parsing the address",
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "expected tcp://host:port"),
        ));
    }
    let stream = match tokio::time::timeout(timeout, TcpStream::connect(addr)).await {
        Ok(Ok(s)) => s,
        Ok(Err(e)) => return Err(LinkError::io(&name, "connecting", e)),
        Err(_) => {
            return Err(LinkError::Timeout {
                device: name,
                timeout,
                partial: Vec::new(),
            });
        }
    };
    if let Err(e) = stream.set_nodelay(true) {
        tracing::debug!(port = %name, error = %e, "cannot set TCP_NODELAY; continuing");
    }
    tracing::debug!(port = %name, "TCP link open");
    Ok(StreamTransport::new(stream, name))
}

/// What a port string names (see the module documentation), parsed without opening anything.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PortSpec {
    /// A serial port path.
    Serial(String),
    /// `host:port` of a serial-to-Ethernet converter.
    Tcp(String),
    /// A Prologix GPIB-USB controller on the serial port at `path`.
    PrologixSerial {
        /// The controller's serial port.
        path: String,
        /// Address and read timeout.
        options: PrologixOptions,
    },
    /// A Prologix GPIB-ETHERNET controller at `host:port`.
    PrologixTcp {
        /// `host:port` (port 1234 filled in when the string had none).
        addr: String,
        /// Address and read timeout.
        options: PrologixOptions,
    },
}

fn bad(spec: &str, what: String) -> LinkError {
    LinkError::io(
        spec,
        "parsing the port string",
        std::io::Error::new(std::io::ErrorKind::InvalidInput, what),
    )
}

/// Parses the `?addr=N&read_tmo_ms=T` part of a Prologix port string.
fn prologix_query(spec: &str, query: Option<&str>) -> Result<PrologixOptions, LinkError> {
    let mut options = PrologixOptions::default();
    let Some(query) = query else {
        return Ok(options);
    };
    for pair in query.split('&') {
        let Some((key, value)) = pair.split_once('=') else {
            return Err(bad(
                spec,
                format!("parameter {pair:?} is not key=value (use addr=N, read_tmo_ms=T)"),
            ));
        };
        match key {
            "addr" => {
                options.addr = value
                    .parse::<u8>()
                    .ok()
                    .filter(|a| *a <= 30)
                    .ok_or_else(|| {
                        bad(
                            spec,
                            format!("addr {value:?} is not a GPIB primary address (0..=30)"),
                        )
                    })?;
            }
            "read_tmo_ms" => {
                let ms = value
                    .parse::<u64>()
                    .ok()
                    .filter(|m| (1..=3000).contains(m))
                    .ok_or_else(|| {
                        bad(
                            spec,
                            format!("read_tmo_ms {value:?} is not a number of ms in 1..=3000"),
                        )
                    })?;
                options.read_tmo = Duration::from_millis(ms);
            }
            other => {
                return Err(bad(
                    spec,
                    format!("unknown parameter {other:?} (use addr=N, read_tmo_ms=T)"),
                ));
            }
        }
    }
    Ok(options)
}

/// Parses a port string (see the module documentation). Errors name the part that is wrong.
pub fn parse_port(spec: &str) -> Result<PortSpec, LinkError> {
    if let Some(rest) = spec.strip_prefix(PROLOGIX_TCP_SCHEME) {
        let (host, query) = match rest.split_once('?') {
            Some((h, q)) => (h, Some(q)),
            None => (rest, None),
        };
        if host.is_empty() {
            return Err(bad(
                spec,
                "no host (expected prologix-tcp://host[:port][?addr=N])".into(),
            ));
        }
        let addr = match host.rsplit_once(':') {
            // an IPv6 literal without a port ("[::1]") has its last colon inside the brackets
            Some((h, port)) if !port.contains(']') => {
                if h.is_empty() {
                    return Err(bad(spec, "no host before the port".into()));
                }
                port.parse::<u16>()
                    .ok()
                    .filter(|p| *p != 0)
                    .ok_or_else(|| bad(spec, format!("port {port:?} is not a TCP port")))?;
                host.to_string()
            }
            _ => format!("{host}:{PROLOGIX_TCP_PORT}"),
        };
        let options = prologix_query(spec, query)?;
        return Ok(PortSpec::PrologixTcp { addr, options });
    }
    if let Some(rest) = spec.strip_prefix(PROLOGIX_SCHEME) {
        let (path, query) = match rest.split_once('?') {
            Some((p, q)) => (p, Some(q)),
            None => (rest, None),
        };
        if path.is_empty() {
            return Err(bad(
                spec,
                "no serial port (expected prologix:/dev/ttyUSB0[?addr=N])".into(),
            ));
        }
        let options = prologix_query(spec, query)?;
        return Ok(PortSpec::PrologixSerial {
            path: path.to_string(),
            options,
        });
    }
    if let Some(addr) = spec.strip_prefix(TCP_SCHEME) {
        return Ok(PortSpec::Tcp(addr.to_string()));
    }
    if spec.is_empty() {
        return Err(bad(spec, "empty port string".into()));
    }
    Ok(PortSpec::Serial(spec.to_string()))
}

/// A link opened by [`open`]: a byte stream with line framing (serial, TCP), or a Prologix GPIB
/// controller over one. Chosen at run time from the port string, so an enum that delegates
/// (the [`Transport`] trait's `impl Future` methods make it not object-safe).
#[derive(Debug)]
pub enum Link {
    /// A serial port or a TCP connection, framed in lines.
    Stream(StreamTransport<DynStream>),
    /// An instrument on GPIB behind a Prologix controller.
    Prologix(PrologixTransport<StreamTransport<DynStream>>),
    /// A LAN instrument's raw SCPI socket: device clear reconnects.
    Socket(SocketTransport),
}

impl Link {
    /// The line-framed byte stream underneath (the controller's link for Prologix).
    pub fn stream(&mut self) -> &mut StreamTransport<DynStream> {
        match self {
            Link::Stream(t) => t,
            Link::Prologix(p) => p.get_mut(),
            Link::Socket(s) => s.get_mut(),
        }
    }
}

impl Transport for Link {
    fn describe(&self) -> &str {
        match self {
            Link::Stream(t) => t.describe(),
            Link::Prologix(t) => t.describe(),
            Link::Socket(t) => t.describe(),
        }
    }
    async fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        match self {
            Link::Stream(t) => t.write_raw(bytes).await,
            Link::Prologix(t) => t.write_raw(bytes).await,
            Link::Socket(t) => t.write_raw(bytes).await,
        }
    }
    async fn send_line(&mut self, line: &str) -> Result<(), LinkError> {
        match self {
            Link::Stream(t) => t.send_line(line).await,
            Link::Prologix(t) => t.send_line(line).await,
            Link::Socket(t) => t.send_line(line).await,
        }
    }
    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        match self {
            Link::Stream(t) => t.read_line(timeout).await,
            Link::Prologix(t) => t.read_line(timeout).await,
            Link::Socket(t) => t.read_line(timeout).await,
        }
    }
    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        match self {
            Link::Stream(t) => t.discard_input().await,
            Link::Prologix(t) => t.discard_input().await,
            Link::Socket(t) => t.discard_input().await,
        }
    }
    async fn read_field(&mut self, sep: u8, timeout: Option<Duration>) -> Result<Field, LinkError> {
        match self {
            Link::Stream(t) => t.read_field(sep, timeout).await,
            Link::Prologix(t) => t.read_field(sep, timeout).await,
            Link::Socket(t) => t.read_field(sep, timeout).await,
        }
    }
    async fn read_until(
        &mut self,
        delimiter: u8,
        timeout: Option<Duration>,
    ) -> Result<String, LinkError> {
        match self {
            Link::Stream(t) => t.read_until(delimiter, timeout).await,
            Link::Prologix(t) => t.read_until(delimiter, timeout).await,
            Link::Socket(t) => t.read_until(delimiter, timeout).await,
        }
    }
    async fn device_clear(&mut self) -> Result<(), LinkError> {
        match self {
            Link::Stream(t) => t.device_clear().await,
            Link::Prologix(t) => t.device_clear().await,
            Link::Socket(t) => t.device_clear().await,
        }
    }
    fn needs_remote_command(&self) -> bool {
        match self {
            Link::Stream(t) => t.needs_remote_command(),
            Link::Prologix(t) => t.needs_remote_command(),
            Link::Socket(t) => t.needs_remote_command(),
        }
    }
    async fn return_to_local(&mut self) -> Result<(), LinkError> {
        match self {
            Link::Stream(t) => t.return_to_local().await,
            Link::Prologix(t) => t.return_to_local().await,
            Link::Socket(t) => t.return_to_local().await,
        }
    }
}

/// Opens a link from a port string (see the module documentation). Serial settings in
/// `options` apply to serial ports, including a Prologix GPIB-USB's (which presents as one);
/// `connect_timeout` to TCP. Stale input is cleared before the link is returned; a Prologix
/// controller is set up and must answer `++ver`.
pub async fn open(spec: &str, options: &LinkOptions) -> Result<Link, LinkError> {
    match parse_port(spec)? {
        PortSpec::Tcp(addr) if options.scpi_socket => {
            let connector = tcp_connector(addr, options.connect_timeout);
            let name = format!(
                "{}{}",
                crate::TCP_SCHEME,
                spec.trim_start_matches(crate::TCP_SCHEME)
            );
            let mut t = SocketTransport::connect(name, connector).await?;
            t.discard_input().await?;
            Ok(Link::Socket(t))
        }
        PortSpec::Tcp(addr) => {
            let mut t = open_tcp(&addr, options.connect_timeout).await?.boxed();
            t.discard_input().await?;
            Ok(Link::Stream(t))
        }
        PortSpec::Serial(path) => Ok(Link::Stream(open_serial(&path, options)?.boxed())),
        PortSpec::PrologixSerial { path, options: p } => {
            let inner = open_serial(&path, options)?.boxed();
            Ok(Link::Prologix(PrologixTransport::open(inner, p).await?))
        }
        PortSpec::PrologixTcp { addr, options: p } => {
            let inner = open_tcp(&addr, options.connect_timeout).await?.boxed();
            Ok(Link::Prologix(PrologixTransport::open(inner, p).await?))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(addr: u8, ms: u64) -> PrologixOptions {
        PrologixOptions {
            addr,
            read_tmo: Duration::from_millis(ms),
            ..PrologixOptions::default()
        }
    }

    #[test]
    fn good_port_strings() {
        assert_eq!(
            parse_port("/dev/ttyUSB0").unwrap(),
            PortSpec::Serial("/dev/ttyUSB0".into())
        );
        assert_eq!(
            parse_port("tcp://10.0.0.5:4001").unwrap(),
            PortSpec::Tcp("10.0.0.5:4001".into())
        );
        assert_eq!(
            parse_port("prologix:/dev/ttyUSB0?addr=22").unwrap(),
            PortSpec::PrologixSerial {
                path: "/dev/ttyUSB0".into(),
                options: opts(22, 1000)
            }
        );
        assert_eq!(
            parse_port("prologix:COM4").unwrap(),
            PortSpec::PrologixSerial {
                path: "COM4".into(),
                options: opts(22, 1000)
            }
        );
        assert_eq!(
            parse_port("prologix-tcp://lab-gpib:1234?addr=5&read_tmo_ms=3000").unwrap(),
            PortSpec::PrologixTcp {
                addr: "lab-gpib:1234".into(),
                options: opts(5, 3000)
            }
        );
        assert_eq!(
            parse_port("prologix-tcp://10.0.0.7").unwrap(),
            PortSpec::PrologixTcp {
                addr: "10.0.0.7:1234".into(),
                options: opts(22, 1000)
            }
        );
        assert_eq!(
            parse_port("prologix-tcp://[::1]?addr=0").unwrap(),
            PortSpec::PrologixTcp {
                addr: "[::1]:1234".into(),
                options: opts(0, 1000)
            }
        );
    }

    #[test]
    fn bad_port_strings_name_the_wrong_part() {
        for (spec, part) in [
            ("prologix:/dev/ttyUSB0?addr=31", "addr \"31\""),
            ("prologix:/dev/ttyUSB0?addr=x", "addr \"x\""),
            ("prologix:/dev/ttyUSB0?adr=22", "unknown parameter \"adr\""),
            ("prologix:/dev/ttyUSB0?addr", "\"addr\" is not key=value"),
            ("prologix:?addr=22", "no serial port"),
            ("prologix-tcp://?addr=22", "no host"),
            ("prologix-tcp://host:http", "port \"http\""),
            ("prologix-tcp://host:0", "port \"0\""),
            ("prologix-tcp://:1234", "no host before the port"),
            ("prologix-tcp://h?read_tmo_ms=0", "read_tmo_ms \"0\""),
            ("prologix-tcp://h?read_tmo_ms=5000", "read_tmo_ms \"5000\""),
            ("", "empty port string"),
        ] {
            let err = parse_port(spec).unwrap_err();
            let msg = err.to_string();
            assert!(msg.contains(part), "{spec}: {msg}");
            assert!(msg.contains("parsing the port string"), "{spec}: {msg}");
        }
    }
}
