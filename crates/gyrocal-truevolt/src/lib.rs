//! # gyrocal-truevolt
//!
//! A driver for the Keysight Truevolt 34460A / 34461A / 34465A / 34470A digital multimeters
//! on a LAN SCPI socket (port 5025), in the multimeter role ([`gyrocal_meter::Multimeter`]).
//!
//! Why it looks the way it does (facts in `shared/docs/instruments.md`; \[U\] marks the
//! unconfirmed ones, each a documented default in [`TimingDefaults`] or [`TruevoltOptions`]):
//!
//! - the model facts (memory, NPLC values, ranges) are written once, in [`facts`]: the CLI
//!   checks a plan against them with [`facts::check`] before anything opens, the driver
//!   before it configures, the simulator serves them;
//! - a Truevolt measures into a memory of 1,000 to 2,000,000 readings and keeps measuring
//!   while the host reads: **stream** acquisition (`SAMP:COUN n`, `INIT`, then
//!   `DATA:REMove? k,WAIT` chunk after chunk) moves every reading while the next ones are
//!   taken, so a 10,000-reading step needs no 512-reading bursts and a 34460A drains its
//!   1,000-reading memory while it fills; the last chunk is a few readings, so the step waits
//!   about a millisecond after its last reading ([`timing`]);
//! - **memory** acquisition (`INIT`, `*OPC?`, `FETC?`, in memory-sized parts) may leave its
//!   last `FETC?` pending ([`gyrocal_meter::Measured::Pending`]) to overlap the table's ramp;
//! - a Truevolt may answer `*IDN?` as a 34401A: it is identified by model
//!   ([`TruevoltMeter`]'s `connect`);
//! - a raw socket has no device clear: the link's ([`gyrocal_link::SocketTransport`])
//!   reconnects, and the driver sends `ABOR` and reads the error queue and `*ESR?` (Power On
//!   bit: the meter was power-cycled, its memory and settings are gone: the link is
//!   re-established and the configuration sent again, and readings it held are
//!   [`gyrocal_meter::ErrorKind::ReadingsLost`]). Retries are counted once, here, and
//!   reported in [`gyrocal_meter::Acquired`];
//! - a meter that answers late (busy, behind a network bridge) is not reconnected and
//!   reconfigured again and again: after a reply timeout the driver waits up to
//!   [`TruevoltOptions::late_reply_wait`] (3 s) on the same connection for the late reply,
//!   throws it away, widens every later deadline by about twice the lateness seen (at most
//!   [`TruevoltOptions::max_reply_delay`], 5 s), and
//!   retries; a reply later than that counts as none, and the failure then says the meter
//!   answers slowly. Readings lost with the memory name what cleared it (a power cycle, or
//!   gyrocal's own reconfiguration), never "power cycle?" by default;
//! - a LAN port that refuses connections (a meter switched off or rebooting) gets the same
//!   come-back window ([`TruevoltOptions::reconnect_timeout`], 30 s) as a meter that accepts
//!   the connection and stays silent.

#[cfg(feature = "driver")]
pub mod error;
pub mod facts;
#[cfg(feature = "driver")]
mod meter;
#[cfg(feature = "driver")]
pub mod timing;

#[cfg(feature = "driver")]
pub use error::{Error, InstrumentError, parse_error};
pub use facts::{FactsError, Model, check};
#[cfg(feature = "driver")]
pub use meter::{PendingFetch, TruevoltMeter, TruevoltOptions, parse_reading};
#[cfg(feature = "driver")]
pub use timing::{Acquisition, TimingDefaults, TruevoltTiming};
