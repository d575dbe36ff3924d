//! [`SocketTransport`]: a raw SCPI socket (a LAN instrument's port 5025), whose device clear is
//! a reconnect.
//!
//! Why a transport of its own: a raw socket has no in-band device clear. The RS-232 clear
//! (the Ctrl-C byte, [`crate::DEVICE_CLEAR`]) would reach a SCPI parser as data, and there is no
//! GPIB bus line to pull. VISA's `viClear()` on a `TCPIP::…::SOCKET` resource is, in effect,
//! "a no-op plus reconnect": the instrument drops the output it owed to a connection that is
//! gone, and the new connection starts with empty buffers. [`SocketTransport::device_clear`]
//! does that: it closes the socket, connects again through its [`Connector`], and throws away
//! whatever is buffered. The instrument's measurement state (an `INIT` in progress, its reading
//! memory, its error queue) is untouched by a reconnect: the driver sends `ABOR`/`*CLS` itself.
//!
//! The connector is how a new connection is made: `TcpStream::connect` to the same address for
//! [`crate::open`] (`tcp://HOST:PORT` with [`crate::LinkOptions::scpi_socket`]), or a fresh
//! in-memory pipe to a simulated instrument in virtual time.

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::AsyncWriteExt;

use crate::{DynStream, Field, LinkError, StreamTransport, Transport};

/// A connection being made.
pub type ConnectFuture = Pin<Box<dyn Future<Output = Result<DynStream, LinkError>> + Send>>;

/// Makes a new connection to the same instrument (see the module documentation).
pub type Connector = Arc<dyn Fn() -> ConnectFuture + Send + Sync>;

/// A line-framed raw socket to a LAN instrument that reconnects on device clear.
pub struct SocketTransport {
    inner: StreamTransport<DynStream>,
    connect: Connector,
    reconnects: u64,
}

impl std::fmt::Debug for SocketTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SocketTransport")
            .field("inner", &self.inner)
            .field("reconnects", &self.reconnects)
            .finish_non_exhaustive()
    }
}

impl SocketTransport {
    /// Wraps an open connection `inner`; `connect` makes the next one on device clear.
    pub fn new(inner: StreamTransport<DynStream>, connect: Connector) -> Self {
        SocketTransport {
            inner,
            connect,
            reconnects: 0,
        }
    }

    /// Connects with `connect` and wraps the connection under the name `name`.
    pub async fn connect(name: impl Into<String>, connect: Connector) -> Result<Self, LinkError> {
        let stream = (connect)().await?;
        Ok(SocketTransport::new(
            StreamTransport::new(stream, name),
            connect,
        ))
    }

    /// How many times the socket was reconnected (device clears).
    pub fn reconnects(&self) -> u64 {
        self.reconnects
    }

    /// The line-framed connection now open.
    pub fn get_mut(&mut self) -> &mut StreamTransport<DynStream> {
        &mut self.inner
    }

    /// Closes the connection and opens a new one (input buffered from the old one is gone).
    ///
    /// A failed connect leaves the transport usable for another attempt (the next device
    /// clear connects again). A refused connection is what a LAN instrument that is switched
    /// off or rebooting gives; the error says so, and it is not the end of the instrument:
    /// a driver's recovery keeps reconnecting within its come-back window, exactly as for an
    /// instrument that accepts the connection and does not answer.
    pub async fn reconnect(&mut self) -> Result<(), LinkError> {
        // a polite close; a peer that is gone already is no error here
        let _ =
            tokio::time::timeout(Duration::from_millis(100), self.inner.get_mut().shutdown()).await;
        let name = self.inner.describe().to_string();
        let stream = (self.connect)().await?;
        self.inner = StreamTransport::new(stream, name);
        self.reconnects += 1;
        tracing::debug!(
            device = self.inner.describe(),
            "socket reconnected (device clear)"
        );
        Ok(())
    }
}

impl Transport for SocketTransport {
    fn describe(&self) -> &str {
        self.inner.describe()
    }
    async fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.inner.write_raw(bytes).await
    }
    async fn send_line(&mut self, line: &str) -> Result<(), LinkError> {
        self.inner.send_line(line).await
    }
    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        self.inner.read_line(timeout).await
    }
    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        self.inner.discard_input().await
    }
    async fn read_field(&mut self, sep: u8, timeout: Option<Duration>) -> Result<Field, LinkError> {
        self.inner.read_field(sep, timeout).await
    }
    async fn read_until(
        &mut self,
        delimiter: u8,
        timeout: Option<Duration>,
    ) -> Result<String, LinkError> {
        self.inner.read_until(delimiter, timeout).await
    }
    /// No byte is sent (a SCPI socket would take it as data): the socket is closed and opened
    /// again, as VISA's `viClear()` does on a raw socket, and stale input is thrown away.
    async fn device_clear(&mut self) -> Result<(), LinkError> {
        self.reconnect().await?;
        self.inner.discard_input().await?;
        Ok(())
    }
    /// A LAN instrument is in remote while a client is connected: no `SYST:REM`.
    fn needs_remote_command(&self) -> bool {
        false
    }
}

/// A connector that opens `tcp://addr` again within `timeout`.
pub fn tcp_connector(addr: String, timeout: Duration) -> Connector {
    Arc::new(move || {
        let addr = addr.clone();
        Box::pin(async move {
            let t = crate::open_tcp(&addr, timeout)
                .await
                .map_err(refusal_explained)?;
            let stream: DynStream = Box::new(t.into_stream());
            Ok(stream)
        })
    })
}

/// Whether a failed connect is the instrument refusing (or resetting) the connection: a LAN
/// instrument switched off, rebooting, or with its socket held by another client.
fn is_refused(e: &LinkError) -> bool {
    matches!(e, LinkError::Io { source, .. } if matches!(
        source.kind(),
        std::io::ErrorKind::ConnectionRefused
            | std::io::ErrorKind::ConnectionReset
            | std::io::ErrorKind::ConnectionAborted
    ))
}

fn refusal_explained(e: LinkError) -> LinkError {
    if !is_refused(&e) {
        return e;
    }
    match e {
        LinkError::Io { device, source, .. } => LinkError::Io {
            device,
            context: "connecting (refused: is the instrument switched on, back from a reboot, \
                      and its socket free?)"
                .into(),
            source,
        },
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio::net::TcpListener;

    /// Against a real local listener: device clear sends no byte, the listener sees a second
    /// connection, and the reply the first connection owed is never read.
    #[tokio::test]
    async fn device_clear_on_a_raw_socket_reconnects_and_sends_nothing() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let server = tokio::spawn(async move {
            // first connection: read the query, answer late (after the clear)
            let (mut a, _) = listener.accept().await.unwrap();
            let mut buf = [0u8; 64];
            let n = a.read(&mut buf).await.unwrap();
            assert_eq!(&buf[..n], b"*IDN?\n");
            // second connection: the reconnect
            let (mut b, _) = listener.accept().await.unwrap();
            // the old one owed a reply: it goes to the closed socket, and what the client
            // sent on it after the query is nothing (no 0x03)
            let _ = a.write_all(b"STALE\n").await;
            let mut rest = Vec::new();
            let _ = tokio::time::timeout(Duration::from_secs(2), a.read_to_end(&mut rest)).await;
            let n = b.read(&mut buf).await.unwrap();
            b.write_all(b"FRESH\n").await.unwrap();
            (rest, buf[..n].to_vec())
        });
        let options = crate::LinkOptions {
            scpi_socket: true,
            ..crate::LinkOptions::default()
        };
        let mut link = crate::open(&format!("tcp://{addr}"), &options)
            .await
            .unwrap();
        assert!(matches!(link, crate::Link::Socket(_)));
        assert!(!link.needs_remote_command());
        link.send_line("*IDN?").await.unwrap();
        link.device_clear().await.unwrap();
        link.send_line("SYST:ERR?").await.unwrap();
        let reply = link.read_line(Some(Duration::from_secs(2))).await.unwrap();
        assert_eq!(reply, "FRESH");
        let (old_rest, new_first) = server.await.unwrap();
        assert!(
            old_rest.is_empty(),
            "bytes after the query on the old socket: {old_rest:?}"
        );
        assert_eq!(new_first, b"SYST:ERR?\n");
    }

    /// A refused reconnect (the instrument switched off) is an error that says so, and the
    /// transport connects again on the next device clear, once the instrument listens again.
    #[tokio::test]
    async fn a_refused_reconnect_says_so_and_the_next_clear_connects_again() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let options = crate::LinkOptions {
            scpi_socket: true,
            ..crate::LinkOptions::default()
        };
        let mut link = crate::open(&format!("tcp://{addr}"), &options)
            .await
            .unwrap();
        let (first, _) = listener.accept().await.unwrap();
        // the instrument goes off: its port refuses connections
        drop(first);
        drop(listener);
        let e = link.device_clear().await.unwrap_err();
        assert!(is_refused(&e), "{e}");
        let text = e.to_string();
        assert!(text.contains(&addr.to_string()), "{text}");
        assert!(
            text.contains("refused: is the instrument switched on"),
            "{text}"
        );
        // back on: the same address listens again, and the next device clear reconnects
        let listener = TcpListener::bind(addr).await.unwrap();
        let server = tokio::spawn(async move {
            let (mut b, _) = listener.accept().await.unwrap();
            let mut buf = [0u8; 16];
            let n = b.read(&mut buf).await.unwrap();
            b.write_all(b"BACK\n").await.unwrap();
            buf[..n].to_vec()
        });
        link.device_clear().await.unwrap();
        link.send_line("*IDN?").await.unwrap();
        let reply = link.read_line(Some(Duration::from_secs(2))).await.unwrap();
        assert_eq!(reply, "BACK");
        assert_eq!(server.await.unwrap(), b"*IDN?\n");
    }

    /// Without `scpi_socket` a `tcp://` link is a serial converter and keeps the 0x03 byte.
    #[tokio::test]
    async fn a_serial_converter_keeps_the_ctrl_c_clear() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let server = tokio::spawn(async move {
            let (mut a, _) = listener.accept().await.unwrap();
            let mut buf = [0u8; 8];
            let n = a.read(&mut buf).await.unwrap();
            buf[..n].to_vec()
        });
        let mut link = crate::open(&format!("tcp://{addr}"), &crate::LinkOptions::default())
            .await
            .unwrap();
        assert!(matches!(link, crate::Link::Stream(_)));
        link.device_clear().await.unwrap();
        assert_eq!(server.await.unwrap(), vec![crate::DEVICE_CLEAR]);
    }
}
