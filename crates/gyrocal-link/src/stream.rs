//! [`StreamTransport`]: line framing over any async byte stream (serial port, TCP socket,
//! in-memory pipe). The framing itself is [`LineCodec`] (a `tokio_util::codec` decoder and
//! encoder); this type adds deadlines, the end of the stream and discarding stale input.

use std::time::Duration;

use bytes::BytesMut;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, DuplexStream};

use crate::codec::{Cut, FrameCodec, LineCodec};
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
///
/// The framing is the codec `C`, [`LineCodec`] unless another [`FrameCodec`] is given with
/// [`StreamTransport::with_codec`] (a prompt-terminated or fixed-length framing is a codec, not
/// a transport).
pub struct StreamTransport<S, C = LineCodec> {
    stream: S,
    name: String,
    buf: BytesMut,
    codec: C,
}

impl<S, C: std::fmt::Debug> std::fmt::Debug for StreamTransport<S, C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StreamTransport")
            .field("name", &self.name)
            .field("buffered", &self.buf.len())
            .field("codec", &self.codec)
            .finish_non_exhaustive()
    }
}

impl<S: AsyncStream> StreamTransport<S> {
    /// Wraps `stream` with the line framing ([`LineCodec`]); `name` is what error messages call
    /// the link.
    pub fn new(stream: S, name: impl Into<String>) -> Self {
        StreamTransport::with_codec(stream, name, LineCodec::new(DEFAULT_MAX_LINE))
    }

    /// Sets the longest line accepted before the input is declared garbled.
    pub fn with_max_line(mut self, max_line: usize) -> Self {
        self.codec = LineCodec::new(max_line);
        self
    }
}

impl<S: AsyncStream, C: FrameCodec> StreamTransport<S, C> {
    /// Wraps `stream` with the framing `codec`.
    pub fn with_codec(stream: S, name: impl Into<String>, codec: C) -> Self {
        StreamTransport {
            stream,
            name: name.into(),
            buf: BytesMut::new(),
            codec,
        }
    }

    /// The codec.
    pub fn codec(&self) -> &C {
        &self.codec
    }

    /// The wrapped stream.
    pub fn get_ref(&self) -> &S {
        &self.stream
    }

    /// The wrapped stream, mutably (for backend-specific calls such as modem lines).
    pub fn get_mut(&mut self) -> &mut S {
        &mut self.stream
    }

    /// The wrapped stream back (input buffered here is dropped).
    pub fn into_stream(self) -> S {
        self.stream
    }

    /// Erases the stream type.
    pub fn boxed(self) -> StreamTransport<DynStream, C>
    where
        S: 'static,
    {
        StreamTransport {
            stream: Box::new(self.stream),
            name: self.name,
            buf: self.buf,
            codec: self.codec,
        }
    }

    /// Decodes one piece (a line, or a field up to `cut`'s separator) out of the buffer.
    fn take(&mut self, cut: Cut) -> Result<Option<Field>, LinkError> {
        self.codec.set_cut(cut);
        match self.codec.decode(&mut self.buf) {
            Ok(None) => Ok(None),
            Ok(Some(Ok(field))) => Ok(Some(field)),
            Ok(Some(Err(g))) => Err(LinkError::Garbled {
                device: self.name.clone(),
                reason: g.reason,
                bytes: g.bytes,
            }),
            Err(e) => Err(LinkError::io(&self.name, "decoding", e)),
        }
    }

    /// Takes the text up to `delimiter` (not included, the delimiter consumed) out of the
    /// buffer, if the delimiter has arrived (a prompt-terminated reply).
    fn take_until(&mut self, delimiter: u8) -> Result<Option<String>, LinkError> {
        let Some(pos) = self.buf.iter().position(|&b| b == delimiter) else {
            return Ok(None);
        };
        let mut text = self.buf.split_to(pos + 1).to_vec();
        text.pop();
        String::from_utf8(text)
            .map(Some)
            .map_err(|e| LinkError::Garbled {
                device: self.name.clone(),
                reason: "reply is not valid text".into(),
                bytes: e.into_bytes(),
            })
    }

    /// Reads until the codec yields a piece, the deadline passes or the peer goes away.
    async fn read_with(&mut self, timeout: Option<Duration>, cut: Cut) -> Result<Field, LinkError> {
        self.read_until_taken(timeout, |s| s.take(cut)).await
    }

    /// Reads until `take` gets something out of the buffer, the deadline passes or the peer
    /// goes away.
    async fn read_until_taken<R>(
        &mut self,
        timeout: Option<Duration>,
        mut take: impl FnMut(&mut Self) -> Result<Option<R>, LinkError>,
    ) -> Result<R, LinkError> {
        let deadline = timeout.map(|t| tokio::time::Instant::now() + t);
        loop {
            if let Some(got) = take(self)? {
                return Ok(got);
            }
            let n = match deadline {
                Some(d) => match tokio::time::timeout_at(d, self.fill()).await {
                    Ok(r) => r?,
                    Err(_) => {
                        return Err(LinkError::Timeout {
                            device: self.name.clone(),
                            timeout: timeout.unwrap_or_default(),
                            partial: self.buf.to_vec(),
                        });
                    }
                },
                None => self.fill().await?,
            };
            if n == 0 {
                return Err(LinkError::Disconnected {
                    device: self.name.clone(),
                    partial: self.buf.split().to_vec(),
                });
            }
        }
    }

    async fn fill(&mut self) -> Result<usize, LinkError> {
        self.buf.reserve(4096);
        self.stream
            .read_buf(&mut self.buf)
            .await
            .map_err(|e| LinkError::io(&self.name, "reading", e))
    }
}

impl<S: AsyncStream, C: FrameCodec> Transport for StreamTransport<S, C> {
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

    /// Encodes the line with the codec (the line and LF) and writes it.
    async fn send_line(&mut self, line: &str) -> Result<(), LinkError> {
        let mut bytes = BytesMut::with_capacity(line.len() + 1);
        self.codec
            .encode(line, &mut bytes)
            .map_err(|e| LinkError::io(&self.name, "encoding", e))?;
        self.write_raw(&bytes).await
    }

    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        Ok(self.read_with(timeout, Cut::Line).await?.text)
    }

    async fn read_field(&mut self, sep: u8, timeout: Option<Duration>) -> Result<Field, LinkError> {
        self.read_with(timeout, Cut::Field(sep)).await
    }

    async fn read_until(
        &mut self,
        delimiter: u8,
        timeout: Option<Duration>,
    ) -> Result<String, LinkError> {
        self.read_until_taken(timeout, |s| s.take_until(delimiter))
            .await
    }

    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        let mut dropped = crate::codec::clear(&mut self.buf);
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
    use crate::codec::Garbled;
    use bytes::BufMut;
    use tokio_util::codec::{Decoder, Encoder};

    /// Another framing is another codec: replies end with a `>` prompt, commands with CR.
    #[derive(Debug)]
    struct Prompt;
    impl Decoder for Prompt {
        type Item = Result<Field, Garbled>;
        type Error = std::io::Error;
        fn decode(&mut self, buf: &mut BytesMut) -> Result<Option<Self::Item>, Self::Error> {
            let Some(pos) = buf.iter().position(|&b| b == b'>') else {
                return Ok(None);
            };
            let reply = buf.split_to(pos + 1);
            let text = String::from_utf8_lossy(&reply[..pos]).trim().to_string();
            Ok(Some(Ok(Field {
                text,
                end_of_line: true,
            })))
        }
    }
    impl Encoder<&str> for Prompt {
        type Error = std::io::Error;
        fn encode(&mut self, line: &str, dst: &mut BytesMut) -> Result<(), Self::Error> {
            dst.put_slice(line.as_bytes());
            dst.put_u8(b'\r');
            Ok(())
        }
    }
    impl FrameCodec for Prompt {
        fn set_cut(&mut self, _: crate::Cut) {}
    }

    #[tokio::test(start_paused = true)]
    async fn another_framing_is_another_codec() {
        let (host, mut dev) = tokio::io::duplex(1024);
        let mut t = StreamTransport::with_codec(host, "table", Prompt);
        t.send_line("PVE").await.unwrap();
        let mut got = [0u8; 4];
        dev.read_exact(&mut got).await.unwrap();
        assert_eq!(&got, b"PVE\r");
        dev.write_all(b"\r\n+10.0000\r\n>").await.unwrap();
        let s = Some(Duration::from_secs(1));
        assert_eq!(t.read_line(s).await.unwrap(), "+10.0000");
        let err = t.read_line(s).await.unwrap_err();
        assert_eq!(err.kind(), ErrorKind::Timeout);
    }

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
}
