//! [`open`]: one entry point that turns a port string into a transport.

use std::time::Duration;

use tokio::net::TcpStream;

use crate::{DynStream, LinkError, LinkOptions, StreamTransport, open_serial};

/// The scheme prefix that selects TCP (an instrument behind a serial-to-Ethernet converter).
pub const TCP_SCHEME: &str = "tcp://";

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

/// Opens a link from a port string: `tcp://host:port` for TCP, anything else is a serial port
/// path (`/dev/ttyUSB0`, `COM3`, a pseudo-terminal's slave path). The result is type-erased so a
/// program can hold either in one type. Stale input is cleared before it is returned.
pub async fn open(
    spec: &str,
    options: &LinkOptions,
) -> Result<StreamTransport<DynStream>, LinkError> {
    if spec.starts_with(TCP_SCHEME) {
        let mut t = open_tcp(spec, options.connect_timeout).await?.boxed();
        crate::Transport::discard_input(&mut t).await?;
        Ok(t)
    } else {
        Ok(open_serial(spec, options)?.boxed())
    }
}
