//! The slow simulated meter's tests, written once for both meter drivers
//! (`crates/gyrocal-hp34401a/tests/slow_sim.rs`, `crates/gyrocal-truevolt/tests/slow_sim.rs`):
//! the DC volts settings they configure, one step's readings taken as the sequencer takes
//! them, and the check that every reading is the simulated input.
//!
//! Included, not a crate, like `plans.rs`: each driver's `tests/common` says
//!
//! ```ignore
//! #[path = "../../../../tests/support/slow_meter.rs"]
//! pub mod slow_meter;
//! ```
//!
//! It needs only `gyrocal-meter`, which both drivers depend on already: the helpers work
//! through the [`Multimeter`] trait, whatever the driver and its link, so the two drivers'
//! slow-meter tests drive their meters the same way and a fix to one reaches the other.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test binary uses a subset

use gyrocal_meter::{Acquired, DcVolts, Measured, Multimeter, Reading};

/// DC volts on the 10 V range at 1 NPLC, autozero on, 50 Hz mains: the settings of the
/// shipped plans, which both simulated meters measure at their usual speed.
pub fn dcv() -> DcVolts {
    DcVolts {
        range_v: Some(10.0),
        nplc: 1.0,
        autozero: true,
        line_hz: 50,
    }
}

/// One step's `n` readings as the sequencer takes them: measured (the last part may stay in
/// the meter) and collected.
pub async fn step<M: Multimeter>(m: &mut M, n: usize) -> Acquired {
    match m.measure(n, true).await.unwrap() {
        Measured::Complete(acq) => acq,
        Measured::Pending(p) => m.collect(p).await.unwrap(),
    }
}

/// Every reading is the meter's input `volts` (within `tolerance`, the simulated meter's
/// noise): no other reply (`1` of `*OPC?`, an error-queue entry, `*ESR?`'s number, an
/// identity) was taken for readings, and none is missing or extra.
pub fn all_readings(acq: &Acquired, n: usize, volts: f64, tolerance: f64) {
    assert_eq!(acq.readings.len(), n, "{:?}", acq.notes);
    for r in &acq.readings {
        assert!(
            matches!(r, Reading::Volts(v) if (v - volts).abs() < tolerance),
            "{r:?} is not a reading of the {volts} V input"
        );
    }
}
