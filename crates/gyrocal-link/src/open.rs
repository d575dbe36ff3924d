//! [`open`]: one entry point that turns a port string into a transport, and [`open_port`] for
//! a port already parsed ([`PortSpec`], whose module documents the port strings).

use std::time::Duration;

use tokio::net::TcpStream;

use crate::port::{PortSpec, TCP_SCHEME};
use crate::prologix::PrologixTransport;
use crate::{
    DynStream, Field, LinkError, LinkOptions, SocketTransport, StreamTransport, Transport,
    open_serial, tcp_connector,
};

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

/// Parses a port string ([`PortSpec::parse`]) as a link error: the port string and
/// "parsing the port string", then the part that is wrong.
pub fn parse_port(spec: &str) -> Result<PortSpec, LinkError> {
    PortSpec::parse(spec).map_err(|e| {
        LinkError::io(
            spec,
            "parsing the port string",
            std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()),
        )
    })
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
    open_port(&parse_port(spec)?, options).await
}

/// Opens a link to a parsed port (see [`open`]): the port a plan holds is opened without
/// being turned back into text and parsed again.
pub async fn open_port(port: &PortSpec, options: &LinkOptions) -> Result<Link, LinkError> {
    match port {
        PortSpec::Tcp { host, port } if options.scpi_socket => {
            let addr = crate::port::PortSpec::Tcp {
                host: host.clone(),
                port: *port,
            };
            let name = addr.to_string();
            let connector = tcp_connector(
                addr.socket_address().unwrap_or_default(),
                options.connect_timeout,
            );
            let mut t = SocketTransport::connect(name, connector).await?;
            t.discard_input().await?;
            Ok(Link::Socket(t))
        }
        PortSpec::Tcp { .. } => {
            let addr = port.socket_address().unwrap_or_default();
            let mut t = open_tcp(&addr, options.connect_timeout).await?.boxed();
            t.discard_input().await?;
            Ok(Link::Stream(t))
        }
        PortSpec::Serial(path) => Ok(Link::Stream(
            open_serial(&path.to_string_lossy(), options)?.boxed(),
        )),
        PortSpec::PrologixSerial { path, options: p } => {
            let inner = open_serial(&path.to_string_lossy(), options)?.boxed();
            Ok(Link::Prologix(
                PrologixTransport::open(inner, p.clone()).await?,
            ))
        }
        PortSpec::PrologixTcp { options: p, .. } => {
            let addr = port.socket_address().unwrap_or_default();
            let inner = open_tcp(&addr, options.connect_timeout).await?.boxed();
            Ok(Link::Prologix(
                PrologixTransport::open(inner, p.clone()).await?,
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PrologixOptions;

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
            PortSpec::Tcp {
                host: "10.0.0.5".into(),
                port: 4001
            }
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
                host: "lab-gpib".into(),
                port: 1234,
                options: opts(5, 3000)
            }
        );
        assert_eq!(
            parse_port("prologix-tcp://10.0.0.7").unwrap(),
            PortSpec::PrologixTcp {
                host: "10.0.0.7".into(),
                port: 1234,
                options: opts(22, 1000)
            }
        );
        assert_eq!(
            parse_port("prologix-tcp://[::1]?addr=0").unwrap(),
            PortSpec::PrologixTcp {
                host: "::1".into(),
                port: 1234,
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
