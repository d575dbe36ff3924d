//! What the 34401A driver's tests share (`mod common;`): the meter's identity and empty error
//! queue as it sends them, the 1 NPLC settings most tests configure, the simulated meter on
//! an in-memory pipe, and a driver connected and configured on a link. The slow simulated
//! meter's helpers, shared with the Truevolt driver's tests, are in [`slow_meter`]
//! (`tests/support/slow_meter.rs`).
//!
//! Written once so a test reads as what it checks, and a change of the meter's defaults (its
//! identity, the simulated meter's seed) is made in one place, not in six test files.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use gyrocal_hp34401a::{AutoZero, DcvConfig, DriverOptions, Hp34401a};
use gyrocal_link::{DynStream, StreamTransport, Transport, memory_pair};
use gyrocal_sim::SignalSource;
use gyrocal_sim::dmm::{DmmConfig, DmmHandle, SimDmm};

/// The slow simulated meter's helpers, shared with the Truevolt driver's tests.
#[path = "../../../../tests/support/slow_meter.rs"]
pub mod slow_meter;

/// The identity the (simulated) 34401A answers to `*IDN?`.
pub const IDN: &str = "HEWLETT-PACKARD,34401A,0,11-5-2";

/// The 34401A's answer to `SYST:ERR?` when its error queue is empty.
pub const NO_ERROR: &str = "+0,\"No error\"";

/// The input the simulated meter measures in most tests.
pub const VOLTS: f64 = 1.234_567;

/// The driver on the simulated meter's in-memory pipe.
pub type Dmm = Hp34401a<StreamTransport<DynStream>>;

/// DC volts on the 10 V range at 1 NPLC, autozero on, 50 Hz mains: the shipped plans'
/// settings (the other fields at their defaults).
pub fn nplc1() -> DcvConfig {
    DcvConfig {
        nplc: 1.0,
        range: Some(10.0),
        autozero: AutoZero::On,
        line_hz: 50,
        ..DcvConfig::default()
    }
}

/// A simulated 34401A measuring `source` (noise drawn from `seed`), served on an in-memory
/// pipe named `sim-dmm`: the driver's end of the pipe and the simulator's handle.
pub fn sim_dmm(
    config: DmmConfig,
    source: Box<dyn SignalSource>,
    seed: u64,
) -> (StreamTransport<DynStream>, DmmHandle) {
    let (link, dev) = memory_pair("sim-dmm");
    let handle = SimDmm::spawn(dev, config, source, seed);
    (link.boxed(), handle)
}

/// A driver with `options` on `link`, connected and configured with `config`.
pub async fn ready<T: Transport>(
    link: T,
    options: DriverOptions,
    config: &DcvConfig,
) -> Hp34401a<T> {
    let mut dmm = Hp34401a::new(link, options);
    dmm.connect().await.unwrap();
    dmm.configure(config).await.unwrap();
    dmm
}
