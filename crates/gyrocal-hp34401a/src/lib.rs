//! # gyrocal-hp34401a
//!
//! A driver for the HP 34401A digital multimeter over RS-232 (or TCP through a serial
//! converter), or over GPIB through a Prologix controller ([`gyrocal_link::PrologixTransport`]:
//! device clear is then `++clr` and no `SYST:REM`/`SYST:LOC` is sent, as the link says through
//! [`gyrocal_link::Transport::needs_remote_command`]), generic over [`gyrocal_link::Transport`] so the same code runs on a real port, a
//! pseudo-terminal, an in-memory pipe to the simulator in virtual time, or a transcript.
//!
//! Why it looks the way it does (see `shared/docs/hp34401a.md`):
//!
//! - the meter answers nothing sensible until `SYST:REM`, so [`Hp34401a::connect`] starts with a
//!   device clear (the interface's: Ctrl-C on RS-232) and `SYST:REM` (RS-232 only), then checks
//!   `*IDN?`;
//! - the meter's RS-232 handshake cannot be used through `serialport`, and queries that pile up
//!   give mixed replies (-410/-420): the driver reads every reply before it sends anything else
//!   and keeps fewer than ~100 characters of commands unacknowledged;
//! - one `READ?` per reading wastes most of a run: [`Hp34401a::acquire`] streams (`READ?` with
//!   `SAMP:COUN`), or uses memory bursts of at most 512 readings (`INIT;*OPC?`, `FETC?`) whose
//!   fetch ([`Hp34401a::fetch`]) can overlap the table moving; [`Strategy::Auto`] picks from the
//!   [`timing`] model, which is public for run estimates;
//! - overloads (±9.9E37) come back as [`Reading::Overload`], never as numbers;
//! - after a timeout or a garbled reply the driver clears the device, drains the error queue and
//!   retries; errors carry an [`ErrorKind`] and [`Error::is_retryable`];
//! - a meter that stops answering, or comes back from a power cycle (in LOCAL, with its
//!   power-on settings and an empty memory), is noticed by [`Hp34401a::recover`] (no answer
//!   after the device clear, error 550, or the Power On bit of `*ESR?`), which then
//!   re-establishes the link as at connect and sends the configuration again, for up to
//!   [`DriverOptions::reconnect_timeout`] ([`Error::NotBack`] after that). The returned
//!   [`Recovery`] (and [`Acquisition::recoveries`]) says so, for the run's log; `acquire` takes
//!   the lost part again, and a burst armed before it cannot be fetched
//!   ([`Error::ReadingsLost`]).
//!
//! Features: `driver` (the default) is all of the above; without it only [`facts`] is built
//! (no async runtime), for the synchronous plan crate.
//!
//! ```no_run
//! # async fn demo() -> Result<(), Box<dyn std::error::Error>> {
//! use gyrocal_hp34401a::{DcvConfig, DriverOptions, Hp34401a, Strategy};
//! let link = gyrocal_link::open("/dev/ttyUSB0", &Default::default()).await?;
//! let mut dmm = Hp34401a::new(link, DriverOptions::default());
//! dmm.connect().await?;
//! dmm.configure(&DcvConfig { nplc: 1.0, range: Some(10.0), ..DcvConfig::default() }).await?;
//! let acq = dmm.acquire(500, Strategy::Auto).await?;
//! println!("{} readings, {} overloads", acq.readings.len(), acq.overloads());
//! dmm.close().await?;
//! # Ok(()) }
//! ```

pub mod facts;
pub use facts::{NPLC_VALUES, RANGES};

#[cfg(feature = "driver")]
mod config;
#[cfg(feature = "driver")]
mod driver;
#[cfg(feature = "driver")]
mod error;
#[cfg(feature = "driver")]
mod meter;
#[cfg(feature = "driver")]
mod reading;
#[cfg(feature = "driver")]
pub mod timing;

#[cfg(feature = "driver")]
pub use config::{AutoZero, DcvConfig, TriggerSource};
#[cfg(feature = "driver")]
pub use driver::{
    Acquisition, Burst, DriverOptions, Hp34401a, Identity, LinkLoss, Progress, ProgressFn, Recovery,
};
#[cfg(feature = "driver")]
pub use error::{Error, ErrorKind, InstrumentError};
/// The SCPI error-queue parser is the meter role's (one copy for every SCPI meter).
#[cfg(feature = "driver")]
pub use gyrocal_meter::parse_error;
#[cfg(feature = "driver")]
pub use meter::{Hp34401aMeter, PendingBurst};
#[cfg(feature = "driver")]
pub use reading::{OVERLOAD, Reading, parse_reading};
#[cfg(feature = "driver")]
pub use timing::{MeterTiming, Strategy, Timing};
