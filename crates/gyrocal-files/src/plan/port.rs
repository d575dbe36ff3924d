//! Where an instrument is connected: a plan's `port = "..."`, parsed once.

use std::fmt;
use std::path::PathBuf;

/// Where an instrument is connected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Port {
    /// A serial device (`/dev/ttyUSB0`, `COM3`, a pseudo-terminal).
    Serial(PathBuf),
    /// A TCP endpoint (`tcp://HOST:PORT`), e.g. a serial-to-Ethernet converter or ACL's port 9878.
    Tcp {
        /// Host name or address (IPv6 without brackets).
        host: String,
        /// TCP port (1..=65535).
        port: u16,
    },
    /// GPIB through a Prologix controller: `prologix:/dev/ttyUSB0?addr=22` (GPIB-USB) or
    /// `prologix-tcp://HOST[:1234]?addr=22` (GPIB-Ethernet). Kept as written: the link layer
    /// (`gyrocal_link::parse_port`) owns the syntax and checks it when the port is opened or
    /// the plan checked (`gyrocal check`).
    Gpib(String),
}

impl Port {
    /// Parses `tcp://HOST:PORT` (IPv6 as `tcp://[::1]:9878`) or a serial device path.
    pub fn parse(s: &str) -> Result<Port, String> {
        if s.trim().is_empty() {
            return Err("must not be empty".into());
        }
        if s.chars().any(char::is_control) {
            return Err(format!("must not contain control characters (got {s:?})"));
        }
        if let Some(rest) = s.strip_prefix("tcp://") {
            let bad = || format!("must be tcp://HOST:PORT with PORT in 1..=65535 (got {s:?})");
            let (host, port) = if let Some(v6) = rest.strip_prefix('[') {
                let (host, after) = v6.split_once(']').ok_or_else(bad)?;
                (host, after.strip_prefix(':').ok_or_else(bad)?)
            } else {
                rest.rsplit_once(':').ok_or_else(bad)?
            };
            if host.is_empty()
                || host.contains(['/', ' '])
                || (host.contains(':') && !rest.starts_with('['))
            {
                return Err(bad());
            }
            let port: u16 = port.parse().map_err(|_| bad())?;
            if port == 0 {
                return Err(bad());
            }
            return Ok(Port::Tcp {
                host: host.to_string(),
                port,
            });
        }
        if s.starts_with("prologix:") || s.starts_with("prologix-tcp://") {
            return Ok(Port::Gpib(s.to_string()));
        }
        if s.contains("://") {
            return Err(format!(
                "unknown scheme: use a device path, tcp://HOST:PORT, prologix:DEVICE?addr=N or \
                 prologix-tcp://HOST?addr=N (got {s:?})"
            ));
        }
        Ok(Port::Serial(PathBuf::from(s)))
    }
}

impl fmt::Display for Port {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Port::Serial(p) => write!(f, "{}", p.display()),
            Port::Tcp { host, port } if host.contains(':') => write!(f, "tcp://[{host}]:{port}"),
            Port::Tcp { host, port } => write!(f, "tcp://{host}:{port}"),
            Port::Gpib(spec) => f.write_str(spec),
        }
    }
}
