//! The server's limits on connections: how many at once, and how long a client may take.
//!
//! [`Limited`] accepts a connection only while it holds one of [`MAX_CONNECTIONS`] slots; past
//! that, new connections wait in the kernel's backlog and are answered as slots free (nothing
//! is refused, nothing is dropped). A slot comes back when its connection closes, and a client
//! cannot keep one by being slow:
//!
//! - every request's head must arrive within [`HEADER_TIMEOUT`], the first as each next one
//!   on a kept-alive connection ([`serve_connections`]: hyper's own per-request header
//!   timeout, which starts when the connection waits for a head, so it is also the idle
//!   keep-alive timeout). A client that connects and says nothing, drips a head a byte at a
//!   time, or sends one request and then drips the next, is closed at the deadline. Note:
//!   `axum::serve` sets hyper no timer, which turns that timeout off, so the server serves
//!   its connections with hyper's HTTP/1 builder itself;
//! - a connection with no traffic either way for [`IDLE_TIMEOUT`] is closed ([`LimitedIo`]: a
//!   client that stops reading its answer; an event stream sends a keep-alive well within
//!   it, so a listening browser stays).
//!
//! Request heads are bounded by the HTTP parser's buffer, and the router refuses URIs and
//! header sets above their limits (`MAX_URI`, [`MAX_HEADER_BYTES`]).

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
/// The longest a connection may take to send a request's head, counted from when it waits
/// for one: from its start, and on a kept-alive connection from the end of the previous
/// answer (the idle keep-alive timeout).
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

/// A connection holding its slot until it closes, closed after [`IDLE_TIMEOUT`] without
/// traffic either way (see the module docs).
pub struct LimitedIo {
    io: TcpStream,
    _slot: OwnedSemaphorePermit,
    /// The idle deadline.
    timer: Pin<Box<Sleep>>,
    idle_timeout: Duration,
}

impl LimitedIo {
    /// Traffic: the idle deadline starts again.
    fn progress(&mut self) {
        let at = Instant::now() + self.idle_timeout;
        self.timer.as_mut().reset(at);
    }

    fn expired(&mut self, cx: &mut Context<'_>) -> Option<std::io::Error> {
        self.timer
            .as_mut()
            .poll(cx)
            .is_ready()
            .then(|| std::io::Error::new(std::io::ErrorKind::TimedOut, "no traffic"))
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
                if buf.filled().len() > before {
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

impl Limited {
    /// The longest a request's head may take (see [`HEADER_TIMEOUT`]).
    pub fn header_timeout(&self) -> Duration {
        self.header_timeout
    }
}

/// Serves every connection `limited` accepts with `app`, forever: hyper's HTTP/1 with its
/// per-request header timeout on (see the module docs).
pub async fn serve_connections(mut limited: Limited, app: axum::Router) {
    use axum::serve::Listener as _;
    let header_timeout = limited.header_timeout();
    loop {
        let (io, _) = limited.accept().await;
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        tokio::spawn(async move {
            let mut http = hyper::server::conn::http1::Builder::new();
            http.timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(header_timeout);
            // an error is the client's (gone, too slow, not HTTP): its connection ends
            let _ = http
                .serve_connection(hyper_util::rt::TokioIo::new(io), service)
                .await;
        });
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
                    let timer = Box::pin(tokio::time::sleep(self.idle_timeout));
                    return (
                        LimitedIo {
                            io,
                            _slot: slot,
                            timer,
                            idle_timeout: self.idle_timeout,
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
