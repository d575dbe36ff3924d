//! The core the simulated SCPI meters share (the HP 34401A in [`crate::dmm`], the Truevolts in
//! [`crate::truevolt`]): what is SCPI or simulator plumbing rather than a model's behaviour.
//!
//! - [`control`]: the faults a meter takes ([`Fault`]), the control messages, the handle and
//!   the counters ([`DmmHandle`], [`DmmInjector`], [`DmmStats`]), and faults armed for a
//!   reading number;
//! - `queue`: the 20-entry error queue with its -350 overflow and the `SYST:ERR?` reply, the
//!   Standard Event register's Power On bit and the `*ESR?` reply;
//! - `params`: numeric and boolean parameters and the SCPI errors their violations queue;
//! - `reply`: reply faults (no reply, garbled, truncated: `garbled`), a slow meter's held
//!   replies, the seeded reading noise and overload clipping, and readings formatted as the
//!   meters send them ([`format_reading`]).
//!
//! Each meter keeps its own command set, wire (RS-232 or GPIB for the 34401A, a LAN socket
//! for the Truevolt) and timing; it calls into this module for the rest, so a change to the
//! shared SCPI behaviour is made once.

pub mod control;
mod params;
mod queue;
mod reply;

pub(crate) use control::{ArmedFaults, Ctl};
pub use control::{DmmHandle, DmmInjector, DmmStats, Fault};
pub(crate) use params::{boolean, keyword, number};
pub use queue::{ERROR_QUEUE_SIZE, ESR_PON};
pub(crate) use queue::{ErrorQueue, EventStatus};
pub(crate) use reply::{Noise, ReplyFault, SlowReplies, clip, format_nr3, garbled, slow_delay};
pub use reply::{OVERLOAD, format_reading};
