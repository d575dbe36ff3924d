//! [`LineCodec`]: the line framing of every gyrocal link, as a `tokio_util::codec` decoder and
//! encoder (the model is tokio-serial's `SerialFramed<C>`).
//!
//! Framing is kept apart from the byte stream so that another framing (a prompt-terminated
//! dialect, fixed-length records) is another codec, not another transport. [`StreamTransport`](crate::StreamTransport)
//! drives this codec over its read buffer and adds what a codec cannot know: deadlines and the
//! end of the stream.
//!
//! [`StreamTransport`](crate::StreamTransport): crate::StreamTransport

use bytes::{Buf, BufMut, BytesMut};
use tokio_util::codec::{Decoder, Encoder};

use crate::Field;

/// A framing a [`StreamTransport`](crate::StreamTransport) can drive: decodes pieces ([`Field`]s, or [`Garbled`]
/// bytes as an item so reading goes on after them), encodes a line to send, and cuts whole
/// lines or fields as [`Transport::read_line`] and [`Transport::read_field`] ask.
/// [`LineCodec`] is the one every current instrument uses; a prompt-terminated dialect would
/// be another implementation.
///
/// [`Transport::read_line`]: crate::Transport::read_line
/// [`Transport::read_field`]: crate::Transport::read_field
pub trait FrameCodec:
    Decoder<Item = Result<Field, Garbled>, Error = std::io::Error>
    + for<'a> Encoder<&'a str, Error = std::io::Error>
    + Send
{
    /// What the next decode cuts.
    fn set_cut(&mut self, cut: Cut);
}

impl FrameCodec for LineCodec {
    fn set_cut(&mut self, cut: Cut) {
        LineCodec::set_cut(self, cut);
    }
}

/// Bytes that cannot be a reply: why, and the bytes (taken out of the buffer).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Garbled {
    /// Why the bytes were rejected.
    pub reason: String,
    /// The offending bytes.
    pub bytes: Vec<u8>,
}

/// What the decoder cuts: whole lines, or pieces of a line up to a separator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Cut {
    /// A whole LF-terminated line ([`Field::end_of_line`] always true).
    #[default]
    Line,
    /// The text up to this separator or the end of the line, whichever comes first.
    Field(u8),
}

/// LF-terminated lines with one trailing CR removed; a partial line stays in the buffer until
/// its LF arrives; more than `max_line` bytes without a terminator are garbled.
///
/// Decoding yields `Ok(Some(Ok(field)))` for a piece, `Ok(Some(Err(garbled)))` for bytes that
/// cannot be a reply (not UTF-8, runaway), and `Ok(None)` when more bytes are needed. Garbled
/// input is an item rather than a decoder error so that a framed stream goes on after it (a
/// `tokio_util` framed reader ends its stream after a decoder error). Encoding a `&str` writes
/// it followed by LF.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LineCodec {
    cut: Cut,
    max_line: usize,
}

impl Default for LineCodec {
    fn default() -> Self {
        LineCodec::new(crate::stream::DEFAULT_MAX_LINE)
    }
}

impl LineCodec {
    /// Lines of at most `max_line` bytes (at least 1).
    pub fn new(max_line: usize) -> Self {
        LineCodec {
            cut: Cut::Line,
            max_line: max_line.max(1),
        }
    }

    /// The longest line accepted.
    pub fn max_line(&self) -> usize {
        self.max_line
    }

    /// What the next decode cuts.
    pub fn set_cut(&mut self, cut: Cut) {
        self.cut = cut;
    }

    /// What the decoder cuts now.
    pub fn cut(&self) -> Cut {
        self.cut
    }
}

impl Decoder for LineCodec {
    type Item = Result<Field, Garbled>;
    type Error = std::io::Error;

    fn decode(&mut self, buf: &mut BytesMut) -> Result<Option<Self::Item>, Self::Error> {
        let sep = match self.cut {
            Cut::Line => None,
            Cut::Field(s) => Some(s),
        };
        let Some(pos) = buf.iter().position(|&b| b == b'\n' || Some(b) == sep) else {
            if buf.len() > self.max_line {
                let bytes = buf.split().to_vec();
                return Ok(Some(Err(Garbled {
                    reason: format!("no line terminator within {} bytes", self.max_line),
                    bytes,
                })));
            }
            return Ok(None);
        };
        let end_of_line = buf[pos] == b'\n';
        let mut text = buf.split_to(pos + 1);
        text.truncate(pos);
        if end_of_line && text.last() == Some(&b'\r') {
            text.truncate(pos - 1);
        }
        Ok(Some(match String::from_utf8(text.to_vec()) {
            Ok(text) => Ok(Field { text, end_of_line }),
            Err(e) => Err(Garbled {
                reason: "reply is not valid text".into(),
                bytes: e.into_bytes(),
            }),
        }))
    }

    /// At the end of the stream a partial line is not a line: nothing more is decoded, and the
    /// partial bytes stay in the buffer for the caller to report.
    fn decode_eof(&mut self, buf: &mut BytesMut) -> Result<Option<Self::Item>, Self::Error> {
        self.decode(buf)
    }
}

impl Encoder<&str> for LineCodec {
    type Error = std::io::Error;

    fn encode(&mut self, line: &str, dst: &mut BytesMut) -> Result<(), Self::Error> {
        dst.reserve(line.len() + 1);
        dst.put_slice(line.as_bytes());
        dst.put_u8(b'\n');
        Ok(())
    }
}

/// Drops everything buffered; returns how many bytes that was.
pub(crate) fn clear(buf: &mut BytesMut) -> usize {
    let n = buf.remaining();
    buf.clear();
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use futures_util::StreamExt;
    use tokio::io::AsyncWriteExt;
    use tokio_util::codec::FramedRead;

    fn field(text: &str, end_of_line: bool) -> Field {
        Field {
            text: text.into(),
            end_of_line,
        }
    }

    #[test]
    fn lines_fields_partials_and_garbage() {
        let mut c = LineCodec::new(16);
        let mut buf = BytesMut::from(&b"+1.0E+00\r\nA,B\npart"[..]);
        assert_eq!(
            c.decode(&mut buf).unwrap(),
            Some(Ok(field("+1.0E+00", true)))
        );
        c.set_cut(Cut::Field(b','));
        assert_eq!(c.decode(&mut buf).unwrap(), Some(Ok(field("A", false))));
        assert_eq!(c.decode(&mut buf).unwrap(), Some(Ok(field("B", true))));
        assert_eq!(c.decode(&mut buf).unwrap(), None);
        assert_eq!(&buf[..], b"part");
        buf.extend_from_slice(b"\xff\n");
        assert!(matches!(c.decode(&mut buf).unwrap(), Some(Err(_))));
        buf.extend_from_slice(&[b'x'; 20]);
        let Some(Err(g)) = c.decode(&mut buf).unwrap() else {
            panic!("runaway line accepted")
        };
        assert_eq!(g.bytes.len(), 20);
        assert!(buf.is_empty());
        let mut out = BytesMut::new();
        c.encode("*IDN?", &mut out).unwrap();
        assert_eq!(&out[..], b"*IDN?\n");
    }

    /// The codec also serves a `tokio_util` framed reader, and garbled input does not end its
    /// stream.
    #[tokio::test]
    async fn works_in_a_framed_reader() {
        let (mut dev, host) = tokio::io::duplex(256);
        dev.write_all(b"ONE\r\n\xfe\nTWO\n").await.unwrap();
        drop(dev);
        let mut framed = FramedRead::new(host, LineCodec::default());
        assert_eq!(
            framed.next().await.unwrap().unwrap(),
            Ok(field("ONE", true))
        );
        assert!(framed.next().await.unwrap().unwrap().is_err());
        assert_eq!(
            framed.next().await.unwrap().unwrap(),
            Ok(field("TWO", true))
        );
        assert!(framed.next().await.is_none());
    }
}
