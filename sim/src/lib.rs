//! # gyrocal-sim
//!
//! The simulated bench gyrocal's tests (and operators in training) run against: an HP 34401A
//! multimeter (or a Keysight Truevolt on its LAN socket, [`truevolt`]), an ACUTROL-style rate table (also served in the experimental Ideal Aerosmith ASCII
//! dialect, [`table::aerosmith`], with the same motion model) and the hemispherical resonator
//! gyro that sits on it.
//!
//! The simulator replaces the *devices*, never the drivers: each simulated instrument serves the
//! raw byte stream of its wire protocol (an in-memory pipe in virtual time, or a pseudo-terminal
//! in real time), so tests exercise the real driver code and the real bytes. Every instrument
//! keeps its time on tokio's clock, so a whole calibration runs in virtual time in seconds.
//!
//! Fidelity follows `shared/docs/hp34401a.md` and `shared/docs/rate-table.md`; what those leave
//! open is configurable, with the default documented on the configuration field. What the
//! simulated SCPI meters share (the error queue, faults and their handle, reply formatting)
//! is written once, in [`scpi`].
//!
//! A bench may also have a thermal chamber ([`chamber`]: a Watlow F4 on Modbus RTU or TCP, or
//! an Espec on text lines) whose physics the gyro's scale factor and bias follow
//! ([`gyro`]'s temperature model), for a temperature series.

pub mod bench;
pub mod chamber;
pub mod dmm;
pub mod faults;
pub mod from_plan;
pub mod gyro;
pub mod prologix;
pub mod scpi;
pub mod signal;
pub mod table;
pub mod truevolt;

pub use signal::SignalSource;
