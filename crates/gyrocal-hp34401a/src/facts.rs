//! The 34401A's facts (from its manual, `shared/docs/hp34401a.md`), with no I/O: built without
//! the `driver` feature too, so the synchronous plan crate checks a plan against them and
//! keeps no copy of its own.

/// The legal integration times in power-line cycles. The meter rejects anything else (-222).
pub const NPLC_VALUES: [f64; 5] = [0.02, 0.2, 1.0, 10.0, 100.0];

/// The DC voltage ranges, in volts.
pub const RANGES: [f64; 5] = [0.1, 1.0, 10.0, 100.0, 1000.0];

/// The power-line frequencies it integrates over, Hz.
pub const LINE_HZ: [u32; 2] = [50, 60];
