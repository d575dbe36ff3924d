//! The [`Transport`] trait: what a driver knows about a link.

use crate::{DEVICE_CLEAR, LinkError};

use std::future::Future;
use std::time::Duration;

/// A line-oriented link to one instrument.
///
/// Lines sent end in LF. Lines received are split on LF with one trailing CR removed; a partial
/// line (no LF yet) is never returned as a line.
pub trait Transport: Send {
    /// A short description for error messages and logs, such as `/dev/ttyUSB0` or
    /// `tcp://10.0.0.5:9878`.
    fn describe(&self) -> &str;

    /// Writes raw bytes (no terminator added) and flushes them.
    fn write_raw(&mut self, bytes: &[u8]) -> impl Future<Output = Result<(), LinkError>> + Send;

    /// Writes one line: `line` followed by LF.
    fn send_line(&mut self, line: &str) -> impl Future<Output = Result<(), LinkError>> + Send {
        let mut bytes = Vec::with_capacity(line.len() + 1);
        bytes.extend_from_slice(line.as_bytes());
        bytes.push(b'\n');
        async move { self.write_raw(&bytes).await }
    }

    /// Reads one complete line, without its terminator. `None` waits for ever.
    fn read_line(
        &mut self,
        timeout: Option<Duration>,
    ) -> impl Future<Output = Result<String, LinkError>> + Send;

    /// Throws away everything received and not yet read (buffered here and already waiting on
    /// the link). Returns how many bytes were dropped. Never waits for more to arrive.
    fn discard_input(&mut self) -> impl Future<Output = Result<usize, LinkError>> + Send;

    /// Reads the next piece of a line: the text up to `sep` or the end of the line, whichever
    /// comes first (neither included; a CR before the LF is stripped). Lets a driver parse a long
    /// reply (thousands of comma-separated readings on one line) as it arrives. `timeout` applies
    /// to this piece.
    ///
    /// The provided implementation returns the whole line as one piece; [`StreamTransport`](crate::StreamTransport) and
    /// [`ScriptedTransport`](crate::ScriptedTransport) split it, so callers must accept either (split every piece on `sep`).
    fn read_field(
        &mut self,
        sep: u8,
        timeout: Option<Duration>,
    ) -> impl Future<Output = Result<Field, LinkError>> + Send {
        let _ = sep;
        async move {
            Ok(Field {
                text: self.read_line(timeout).await?,
                end_of_line: true,
            })
        }
    }

    /// Reads up to and including the byte `delimiter` and returns the text before it, line
    /// terminators included (CR and LF are not stripped). For protocols whose replies end with
    /// a prompt that is not followed by a line terminator, such as the `>` of an Ideal Aerosmith
    /// controller. `timeout` applies to the whole read; bytes after the delimiter stay buffered.
    ///
    /// Added beside `read_line` for prompt-terminated replies; the provided implementation
    /// fails with an [`LinkError::Io`] of kind [`std::io::ErrorKind::Unsupported`].
    /// [`StreamTransport`](crate::StreamTransport) and [`ScriptedTransport`](crate::ScriptedTransport) implement it.
    fn read_until(
        &mut self,
        delimiter: u8,
        timeout: Option<Duration>,
    ) -> impl Future<Output = Result<String, LinkError>> + Send {
        let _ = (delimiter, timeout);
        let device = self.describe().to_string();
        async move {
            Err(LinkError::io(
                device,
                "reading up to a prompt",
                std::io::Error::from(std::io::ErrorKind::Unsupported),
            ))
        }
    }

    /// Device clear, as an operation of the interface (VISA's `viClear()`): tells the
    /// instrument to abort what it is doing and empty its input and output buffers, and throws
    /// away the input already received here. A reply the instrument had begun may still arrive
    /// a moment later: a caller that needs a clean link waits a settle time and calls
    /// [`Transport::discard_input`] again.
    ///
    /// How it is done belongs to the interface:
    /// - RS-232 (the provided implementation, used by [`StreamTransport`](crate::StreamTransport) and
    ///   [`ScriptedTransport`](crate::ScriptedTransport)): the Ctrl-C byte [`DEVICE_CLEAR`](crate::DEVICE_CLEAR), the 34401A's RS-232 device
    ///   clear, then [`Transport::discard_input`]. A `tcp://` link is by default an RS-232
    ///   instrument behind a serial-to-Ethernet converter, so it gets the same byte, passed
    ///   through.
    /// - A LAN instrument's raw SCPI socket ([`SocketTransport`](crate::SocketTransport), `tcp://` opened with
    ///   [`LinkOptions::scpi_socket`](crate::LinkOptions::scpi_socket)): no byte at all (the parser would take it as data);
    ///   the socket is closed and connected again, as `viClear()` does on a socket, so the
    ///   instrument drops the output it owed.
    /// - GPIB through a Prologix controller ([`PrologixTransport`](crate::PrologixTransport)): `++clr`, the bus's
    ///   Selected Device Clear.
    fn device_clear(&mut self) -> impl Future<Output = Result<(), LinkError>> + Send {
        async move {
            self.write_raw(&[DEVICE_CLEAR]).await?;
            self.discard_input().await?;
            Ok(())
        }
    }

    /// Whether the instrument must be put in remote by a command of its own (`SYST:REM` on the
    /// 34401A's RS-232 port) and handed back with another (`SYST:LOC`). True for RS-232 (the
    /// provided implementation); false over GPIB, where the bus's REN line does it and the
    /// 34401A does not accept those commands (they are RS-232-only in its manual).
    fn needs_remote_command(&self) -> bool {
        true
    }

    /// Hands the instrument back to its front panel at the interface level (VISA's
    /// `viGpibControlREN`): nothing on RS-232 (the instrument's own command does it, see
    /// [`Transport::needs_remote_command`]; the provided implementation), `++loc` through a
    /// Prologix controller.
    fn return_to_local(&mut self) -> impl Future<Output = Result<(), LinkError>> + Send {
        async { Ok(()) }
    }
}

/// A piece of a line returned by [`Transport::read_field`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Field {
    /// The text, without the separator or the line terminator.
    pub text: String,
    /// True when the piece ended the line (LF), false when it ended at the separator.
    pub end_of_line: bool,
}

impl<T: Transport + ?Sized> Transport for &mut T {
    fn describe(&self) -> &str {
        (**self).describe()
    }
    fn write_raw(&mut self, bytes: &[u8]) -> impl Future<Output = Result<(), LinkError>> + Send {
        (**self).write_raw(bytes)
    }
    fn send_line(&mut self, line: &str) -> impl Future<Output = Result<(), LinkError>> + Send {
        (**self).send_line(line)
    }
    fn read_line(
        &mut self,
        timeout: Option<Duration>,
    ) -> impl Future<Output = Result<String, LinkError>> + Send {
        (**self).read_line(timeout)
    }
    fn discard_input(&mut self) -> impl Future<Output = Result<usize, LinkError>> + Send {
        (**self).discard_input()
    }
    fn read_field(
        &mut self,
        sep: u8,
        timeout: Option<Duration>,
    ) -> impl Future<Output = Result<Field, LinkError>> + Send {
        (**self).read_field(sep, timeout)
    }
    fn read_until(
        &mut self,
        delimiter: u8,
        timeout: Option<Duration>,
    ) -> impl Future<Output = Result<String, LinkError>> + Send {
        (**self).read_until(delimiter, timeout)
    }
    fn device_clear(&mut self) -> impl Future<Output = Result<(), LinkError>> + Send {
        (**self).device_clear()
    }
    fn needs_remote_command(&self) -> bool {
        (**self).needs_remote_command()
    }
    fn return_to_local(&mut self) -> impl Future<Output = Result<(), LinkError>> + Send {
        (**self).return_to_local()
    }
}
