//! # gyrocal-link
//!
//! The async, line-oriented transport every gyrocal instrument driver talks through.
//!
//! Instruments on RS-232 (the HP 34401A, a rate table behind a serial converter) speak lines of
//! text. The drivers only need a few things from a link: send a line, read one complete line (or
//! a field of it) with a deadline, write raw bytes, throw away stale input, clear the device
//! the way the interface does it ([`Transport::device_clear`]: Ctrl-C on RS-232, `++clr` on
//! GPIB), and know whether the instrument needs a remote command
//! ([`Transport::needs_remote_command`]). [`Transport`] is exactly that, so the protocol code is
//! generic over the link and the same driver runs on a real serial port, a pseudo-terminal, a
//! TCP socket, GPIB behind a Prologix controller ([`PrologixTransport`]), an in-memory pipe
//! driven in virtual time, or a [`ScriptedTransport`] that checks the exact bytes a driver
//! writes.
//!
//! The framing is a `tokio_util::codec` decoder and encoder, [`LineCodec`] (the model is
//! tokio-serial's `SerialFramed<C>`), which [`StreamTransport`] drives over its read buffer.
//! (A controller whose replies end with a prompt and no line terminator is read with
//! [`Transport::read_until`].)
//!
//! Why lines are cut here and not in the drivers: a reply that arrives in pieces (a serial port
//! hands over bytes as they come) must never be mistaken for a whole reply, and every driver would
//! otherwise re-implement the same buffering, CR stripping and timeout handling.
//!
//! Opening: [`open`] takes a port string (`/dev/ttyUSB0`, `COM3`, a pseudo-terminal path,
//! `tcp://host:port`, or a Prologix GPIB controller: `prologix:/dev/ttyUSB0?addr=22`,
//! `prologix-tcp://host:1234?addr=22`) and [`LinkOptions`] (baud 300–9600, framing
//! 8N2/7E2/7O2) and returns a [`Link`]: a type-erased [`StreamTransport<DynStream>`] or a
//! [`PrologixTransport`] over one. [`memory_pair`] gives an in-memory link for tests in
//! virtual time, [`pseudo_terminal`] a pseudo-terminal pair for tests through the serial code.

//! Features: `io` (the default) is everything above; without it only [`facts`] (baud rates,
//! framings, the device-clear byte) and [`port`] (a port string parsed into [`PortSpec`]) are
//! built, with no async runtime, for the synchronous plan crate: a plan holds its ports as
//! this type, parsed once.

pub mod facts;
pub mod port;
pub use facts::{DEVICE_CLEAR, Framing, SUPPORTED_BAUDS};
pub use port::{
    DEFAULT_GPIB_ADDRESS, PROLOGIX_SCHEME, PROLOGIX_TCP_PORT, PROLOGIX_TCP_SCHEME, PortError,
    PortErrorKind, PortSpec, PrologixOptions, TCP_SCHEME,
};

#[cfg(feature = "io")]
mod codec;
#[cfg(feature = "io")]
mod error;
#[cfg(feature = "io")]
mod open;
#[cfg(feature = "io")]
mod prologix;
#[cfg(feature = "io")]
mod scripted;
#[cfg(feature = "io")]
mod serial;
#[cfg(feature = "io")]
mod socket;
#[cfg(feature = "io")]
mod stream;

#[cfg(feature = "io")]
pub use codec::{Cut, FrameCodec, Garbled, LineCodec};
#[cfg(feature = "io")]
pub use error::{ErrorKind, LinkError, show_bytes};
#[cfg(feature = "io")]
pub use open::{Link, open, open_port, open_tcp, parse_port};
#[cfg(feature = "io")]
pub use prologix::{ESC, PrologixTransport, escape};
#[cfg(feature = "io")]
pub use scripted::{ScriptStep, ScriptedTransport};
#[cfg(all(unix, feature = "io"))]
pub use serial::pseudo_terminal;
#[cfg(feature = "io")]
pub use serial::{LinkOptions, open_serial};
#[cfg(feature = "io")]
pub use socket::{ConnectFuture, Connector, SocketTransport, tcp_connector};
#[cfg(feature = "io")]
pub use stream::{AsyncStream, DynStream, StreamTransport, memory_pair};
#[cfg(feature = "io")]
pub use tokio_serial::SerialStream;

#[cfg(feature = "io")]
mod transport;
#[cfg(feature = "io")]
pub use transport::{Field, Transport};
