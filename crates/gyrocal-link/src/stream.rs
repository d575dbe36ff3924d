//! [`StreamTransport`]: line framing over any async byte stream (serial port, TCP socket,
//! in-memory pipe).

use std::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream};

use crate::{Field, LinkError, Transport};

/// Any bidirectional async byte stream that can back a [`StreamTransport`].
pub trait AsyncStream: AsyncRead + AsyncWrite + Send + Unpin {}
impl<T: AsyncRead + AsyncWrite + Send + Unpin> AsyncStream for T {}

/// A type-erased stream, so a program can pick serial or TCP at run time and still hand the
/// drivers one concrete transport type.
pub type DynStream = Box<dyn AsyncStream>;

/// Default longest line accepted: a `FETC?` of 512 readings is 8 KiB; this leaves room for
/// several times that while still catching a runaway stream of bytes without a terminator.
pub const DEFAULT_MAX_LINE: usize = 256 * 1024;

/// Line framing over a byte stream: buffers input, returns whole LF-terminated lines with a
/// trailing CR removed, and keeps any bytes after the LF for the next call.
pub struct StreamTransport<S> {
    stream: S,
    name: String,
    buf: Vec<u8>,
    max_line: usize,
}

impl<S> std::fmt::Debug for StreamTransport<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamTransport")
            .field("name", &self.name)
            .field("buffered", &self.buf.len())
            .field("max_line", &self.max_line)
            .finish_non_exhaustive()
    }
}

impl<S: AsyncStream> StreamTransport<S> {
    /// Wraps `stream`; `name` is what error messages call the link.
    pub fn new(stream: S, name: impl Into<String>) -> Self {
        StreamTransport {
            stream,
            name: name.into(),
            buf: Vec::new(),
            max_line: DEFAULT_MAX_LINE,
        }
    }

    /// Sets the longest line accepted before the input is declared garbled.
    pub fn with_max_line(mut self, max_line: usize) -> Self {
        self.max_line = max_line.max(1);
        self
    }

    /// The wrapped stream.
    pub fn get_ref(&self) -> &S {
        &self.stream
    }

    /// The wrapped stream, mutably (for backend-specific calls such as modem lines).
    pub fn get_mut(&mut self) -> &mut S {
        &mut self.stream
    }

    /// Erases the stream type.
    pub fn boxed(self) -> StreamTransport<DynStream>
    where
        S: 'static,
    {
        StreamTransport {
            stream: Box::new(self.stream),
            name: self.name,
            buf: self.buf,
            max_line: self.max_line,
        }
    }

    /// Takes one complete line out of the buffer, if there is one.
    fn take_line(&mut self) -> Option<Result<String, LinkError>> {
        let pos = self.buf.iter().position(|&b| b == b'\n')?;
        let mut line: Vec<u8> = self.buf.drain(..=pos).collect();
        line.pop(); // LF
        if line.last() == Some(&b'\r') {
            line.pop();
        }
        Some(String::from_utf8(line).map_err(|e| LinkError::Garbled {
            device: self.name.clone(),
            reason: "reply is not valid text".into(),
            bytes: e.into_bytes(),
        }))
    }

    /// Takes one piece (up to `sep` or LF) out of the buffer, if there is one.
    fn take_field(&mut self, sep: u8) -> Option<Result<Field, LinkError>> {
        let pos = self.buf.iter().position(|&b| b == b'\n' || b == sep)?;
        let end_of_line = self.buf[pos] == b'\n';
        let mut text: Vec<u8> = self.buf.drain(..=pos).collect();
        text.pop();
        if end_of_line && text.last() == Some(&b'\r') {
            text.pop();
        }
        Some(
            String::from_utf8(text)
                .map(|text| Field { text, end_of_line })
                .map_err(|e| LinkError::Garbled {
                    device: self.name.clone(),
                    reason: "reply is not valid text".into(),
                    bytes: e.into_bytes(),
                }),
        )
    }

    /// Takes the text up to `delimiter` (not included, the delimiter consumed) out of the
    /// buffer, if the delimiter has arrived.
    fn take_until(&mut self, delimiter: u8) -> Option<Result<String, LinkError>> {
        let pos = self.buf.iter().position(|&b| b == delimiter)?;
        let mut text: Vec<u8> = self.buf.drain(..=pos).collect();
        text.pop();
        Some(String::from_utf8(text).map_err(|e| LinkError::Garbled {
            device: self.name.clone(),
            reason: "reply is not valid text".into(),
            bytes: e.into_bytes(),
        }))
    }

    /// Reads until `take` yields something, the deadline passes or the peer goes away.
    async fn read_with<R>(
        &mut self,
        timeout: Option<Duration>,
        mut take: impl FnMut(&mut Self) -> Option<Result<R, LinkError>>,
    ) -> Result<R, LinkError> {
        let deadline = timeout.map(|t| tokio::time::Instant::now() + t);
        loop {
            if let Some(item) = take(self) {
                return item;
            }
            if self.buf.len() > self.max_line {
                let bytes = std::mem::take(&mut self.buf);
                return Err(LinkError::Garbled {
                    device: self.name.clone(),
                    reason: format!("no line terminator within {} bytes", self.max_line),
                    bytes,
                });
            }
            let n = match deadline {
                Some(d) => match tokio::time::timeout_at(d, self.fill()).await {
                    Ok(r) => r?,
                    Err(_) => {
                        return Err(LinkError::Timeout {
                            device: self.name.clone(),
                            timeout: timeout.unwrap_or_default(),
                            partial: self.buf.clone(),
                        });
                    }
                },
                None => self.fill().await?,
            };
            if n == 0 {
                return Err(LinkError::Disconnected {
                    device: self.name.clone(),
                    partial: std::mem::take(&mut self.buf),
                });
            }
        }
    }

    async fn fill(&mut self) -> Result<usize, LinkError> {
        let mut chunk = [0u8; 4096];
        let n = self
            .stream
            .read(&mut chunk)
            .await
            .map_err(|e| LinkError::io(&self.name, "reading", e))?;
        self.buf.extend_from_slice(&chunk[..n]);
        Ok(n)
    }
}

impl<S: AsyncStream> Transport for StreamTransport<S> {
    fn describe(&self) -> &str {
        &self.name
    }

    async fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let res = async {
            self.stream.write_all(bytes).await?;
            self.stream.flush().await
        }
        .await;
        res.map_err(|e| match e.kind() {
            std::io::ErrorKind::BrokenPipe
            | std::io::ErrorKind::ConnectionReset
            | std::io::ErrorKind::ConnectionAborted
            | std::io::ErrorKind::NotConnected => LinkError::Disconnected {
                device: self.name.clone(),
                partial: Vec::new(),
            },
            _ => LinkError::io(&self.name, "writing", e),
        })
    }

    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        self.read_with(timeout, Self::take_line).await
    }

    async fn read_field(&mut self, sep: u8, timeout: Option<Duration>) -> Result<Field, LinkError> {
        self.read_with(timeout, |s| s.take_field(sep)).await
    }

    async fn read_until(
        &mut self,
        delimiter: u8,
        timeout: Option<Duration>,
    ) -> Result<String, LinkError> {
        self.read_with(timeout, |s| s.take_until(delimiter)).await
    }

    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        let mut dropped = std::mem::take(&mut self.buf).len();
        loop {
            // A zero timeout still polls the read once: whatever is already waiting is taken,
            // and nothing is waited for.
            match tokio::time::timeout(Duration::ZERO, self.fill()).await {
                Ok(Ok(0)) | Err(_) => break,
                Ok(Ok(n)) => {
                    dropped += n;
                    self.buf.clear();
                }
                Ok(Err(e)) => return Err(e),
            }
        }
        Ok(dropped)
    }
}

/// An in-memory link: the driver's transport and the raw stream a simulated device serves.
/// Deterministic and instant, so whole calibration runs can go in tokio's virtual time.
pub fn memory_pair(name: impl Into<String>) -> (StreamTransport<DuplexStream>, DuplexStream) {
    let (host, device) = tokio::io::duplex(64 * 1024);
    (StreamTransport::new(host, name), device)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ErrorKind;

    #[tokio::test(start_paused = true)]
    async fn lines_are_split_and_cr_stripped() {
        let (mut t, mut dev) = memory_pair("mem");
        dev.write_all(b"+1.0E+00\r\nNEXT\npart").await.unwrap();
        assert_eq!(
            t.read_line(Some(Duration::from_secs(1))).await.unwrap(),
            "+1.0E+00"
        );
        assert_eq!(
            t.read_line(Some(Duration::from_secs(1))).await.unwrap(),
            "NEXT"
        );
        let err = t.read_line(Some(Duration::from_secs(1))).await.unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Timeout);
        assert!(err.to_string().contains("part"), "{err}");
        // the partial line is kept and completed by later bytes
        dev.write_all(b"ial\n").await.unwrap();
        assert_eq!(
            t.read_line(Some(Duration::from_secs(1))).await.unwrap(),
            "partial"
        );
    }

    #[tokio::test(start_paused = true)]
    async fn eof_is_disconnected_and_discard_drops_pending() {
        let (mut t, mut dev) = memory_pair("mem");
        dev.write_all(b"stale\nstale2\n").await.unwrap();
        tokio::task::yield_now().await;
        assert_eq!(t.discard_input().await.unwrap(), 13);
        t.send_line("*IDN?").await.unwrap();
        let mut got = [0u8; 6];
        dev.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"*IDN?\n");
        drop(dev);
        let err = t.read_line(None).await.unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Disconnected);
    }

    #[tokio::test(start_paused = true)]
    async fn non_utf8_and_runaway_lines_are_garbled() {
        let (t, mut dev) = memory_pair("mem");
        let mut t = t.with_max_line(16);
        dev.write_all(b"\xff\xfe\n").await.unwrap();
        let err = t.read_line(Some(Duration::from_secs(1))).await.unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Garbled);
        dev.write_all(&[b'x'; 40]).await.unwrap();
        let err = t.read_line(Some(Duration::from_secs(1))).await.unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Garbled);
    }

    #[tokio::test(start_paused = true)]
    async fn read_until_a_prompt_without_line_end() {
        let (mut t, mut dev) = memory_pair("mem");
        let s = Some(Duration::from_secs(1));
        dev.write_all(b"10.0000\r\n>\r\n>").await.unwrap();
        assert_eq!(t.read_until(b'>', s).await.unwrap(), "10.0000\r\n");
        assert_eq!(t.read_until(b'>', s).await.unwrap(), "\r\n");
        dev.write_all(b"partial").await.unwrap();
        let err = t.read_until(b'>', s).await.unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Timeout);
        dev.write_all(b"?\r>").await.unwrap();
        assert_eq!(t.read_until(b'>', s).await.unwrap(), "partial?\r");
    }

    #[tokio::test(start_paused = true)]
    async fn fields_split_on_separator_and_line_end() {
        let (mut t, mut dev) = memory_pair("mem");
        dev.write_all(b"+1.0E+00,+2.0E+00,+3.0").await.unwrap();
        let s = Some(Duration::from_secs(1));
        let f = t.read_field(b',', s).await.unwrap();
        assert_eq!((f.text.as_str(), f.end_of_line), ("+1.0E+00", false));
        let f = t.read_field(b',', s).await.unwrap();
        assert_eq!((f.text.as_str(), f.end_of_line), ("+2.0E+00", false));
        // an unterminated last piece is not returned
        assert_eq!(
            t.read_field(b',', s).await.unwrap_err().kind(),
            ErrorKind::Timeout
        );
        dev.write_all(b"E+00\r\nNEXT\n").await.unwrap();
        let f = t.read_field(b',', s).await.unwrap();
        assert_eq!((f.text.as_str(), f.end_of_line), ("+3.0E+00", true));
        assert_eq!(t.read_line(s).await.unwrap(), "NEXT");
    }
}
