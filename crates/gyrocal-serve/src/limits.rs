//! The server's limits on connections: how many at once, and how long a client may take.
//!
//! [`Limited`] accepts a connection only while it holds one of [`MAX_CONNECTIONS`] slots; past
//! that, new connections wait in the kernel's backlog and are answered as slots free (nothing
//! is refused, nothing is dropped). A slot comes back when its connection closes, and a client
//! cannot keep one by being slow ([`LimitedIo`]): the head of its first request must arrive
//! within [`HEADER_TIMEOUT`] (a client that connects and says nothing, or drips its headers a
//! byte at a time, is closed), and a connection with no traffic either way for
//! [`IDLE_TIMEOUT`] is closed (an event stream sends a keep-alive well within it, so a
//! listening browser stays). Request heads are bounded by the HTTP parser's buffer, and the
//! router refuses URIs and header sets above their limits (`MAX_URI`, [`MAX_HEADER_BYTES`]).

use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};
use tokio::time::{Instant, Sleep};

/// The most open connections; more wait in the kernel's backlog.
pub const MAX_CONNECTIONS: usize = 256;
/// The longest a new connection may take to send its first request's head.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(10);
/// The longest a connection may stay without traffic either way (an event stream's
/// keep-alive comes every 15 s).
pub const IDLE_TIMEOUT: Duration = Duration::from_secs(60);
/// The most bytes of request headers (names and values) accepted.
pub const MAX_HEADER_BYTES: usize = 16 * 1024;

/// A listener that holds at most [`MAX_CONNECTIONS`] connections open (see the module docs).
pub struct Limited {
    inner: TcpListener,
    slots: Arc<Semaphore>,
    header_timeout: Duration,
    idle_timeout: Duration,
}

impl Limited {
    /// `listener` with the default limits.
    pub fn new(listener: TcpListener) -> Limited {
        Limited::with(listener, MAX_CONNECTIONS, HEADER_TIMEOUT, IDLE_TIMEOUT)
    }

    /// `listener` with explicit limits (tests).
    pub fn with(
        listener: TcpListener,
        connections: usize,
        header_timeout: Duration,
        idle_timeout: Duration,
    ) -> Limited {
        Limited {
            inner: listener,
            slots: Arc::new(Semaphore::new(connections)),
            header_timeout,
            idle_timeout,
        }
    }
}

/// A connection holding its slot until it closes, closed when too slow (see the module docs).
pub struct LimitedIo {
    io: TcpStream,
    _slot: OwnedSemaphorePermit,
    /// The head deadline until the first head is complete, then the idle deadline.
    timer: Pin<Box<Sleep>>,
    idle_timeout: Duration,
    /// How many bytes of `\r\n\r\n` the last bytes read matched (4: the first head is in).
    head: usize,
}

impl LimitedIo {
    fn head_done(&self) -> bool {
        self.head >= 4
    }

    /// Follows the end of the first request's head through `bytes`.
    fn scan(&mut self, bytes: &[u8]) {
        const END: &[u8; 4] = b"\r\n\r\n";
        for &b in bytes {
            if self.head_done() {
                return;
            }
            self.head = if b == END[self.head] {
                self.head + 1
            } else if b == END[0] {
                1
            } else {
                0
            };
        }
    }

    /// Traffic: once the first head is in, the idle deadline starts again.
    fn progress(&mut self) {
        if self.head_done() {
            let at = Instant::now() + self.idle_timeout;
            self.timer.as_mut().reset(at);
        }
    }

    fn expired(&mut self, cx: &mut Context<'_>) -> Option<std::io::Error> {
        self.timer.as_mut().poll(cx).is_ready().then(|| {
            let what = if self.head_done() {
                "no traffic"
            } else {
                "no complete request head"
            };
            std::io::Error::new(std::io::ErrorKind::TimedOut, what)
        })
    }
}

impl AsyncRead for LimitedIo {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.io).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                let new = buf.filled()[before..].to_vec();
                if !new.is_empty() {
                    let was = self.head_done();
                    self.scan(&new);
                    if !was && self.head_done() {
                        // the first head is in: from now on the idle deadline
                        let at = Instant::now() + self.idle_timeout;
                        self.timer.as_mut().reset(at);
                    }
                    self.progress();
                }
                Poll::Ready(Ok(()))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            Poll::Pending => match self.expired(cx) {
                Some(e) => Poll::Ready(Err(e)),
                None => Poll::Pending,
            },
        }
    }
}

impl AsyncWrite for LimitedIo {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        match Pin::new(&mut self.io).poll_write(cx, buf) {
            Poll::Ready(Ok(n)) => {
                if n > 0 {
                    self.progress();
                }
                Poll::Ready(Ok(n))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
            // a client that reads nothing: its writes stall, and it is closed at the deadline
            Poll::Pending => match self.expired(cx) {
                Some(e) => Poll::Ready(Err(e)),
                None => Poll::Pending,
            },
        }
    }
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.io).poll_flush(cx)
    }
    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.io).poll_shutdown(cx)
    }
}

impl axum::serve::Listener for Limited {
    type Io = LimitedIo;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (LimitedIo, SocketAddr) {
        loop {
            let Ok(slot) = self.slots.clone().acquire_owned().await else {
                // the semaphore is never closed; wait rather than spin
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            };
            match self.inner.accept().await {
                Ok((io, addr)) => {
                    let _ = io.set_nodelay(true);
                    let timer = Box::pin(tokio::time::sleep(self.header_timeout));
                    return (
                        LimitedIo {
                            io,
                            _slot: slot,
                            timer,
                            idle_timeout: self.idle_timeout,
                            head: 0,
                        },
                        addr,
                    );
                }
                Err(e) => {
                    tracing::warn!("accept: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    }

    fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.inner.local_addr()
    }
}
