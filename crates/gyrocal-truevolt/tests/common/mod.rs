//! What the Truevolt driver's tests share (`mod common;`): the simulated Truevolt served on a
//! LAN port of its own and the driver's socket connected to it, and a connection the meter's
//! port refuses. The slow simulated meter's helpers, shared with the 34401A driver's tests,
//! are in [`slow_meter`] (`tests/support/slow_meter.rs`).

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use gyrocal_link::{ConnectFuture, Connector, LinkError, SocketTransport};
use gyrocal_sim::dmm::DmmHandle;
use gyrocal_sim::signal::Constant;
use gyrocal_sim::truevolt::{SimTruevolt, TruevoltConfig};

/// The slow simulated meter's helpers, shared with the 34401A driver's tests.
#[path = "../../../../tests/support/slow_meter.rs"]
pub mod slow_meter;

/// The input the simulated Truevolt measures.
pub const VOLTS: f64 = 2.5;

/// The address the driver connects to (it names the meter in every message).
pub const ADDRESS: &str = "tcp://sim:5025";

/// A simulated Truevolt measuring [`VOLTS`] (noise from seed 7), and the driver's socket
/// connected to its LAN port through `connector` (the port's own connector, or one that
/// wraps it: `|c| c` for the port as it is).
pub async fn sim_truevolt(
    config: TruevoltConfig,
    connector: impl FnOnce(Connector) -> Connector,
) -> (SocketTransport, DmmHandle) {
    let (handle, port) = SimTruevolt::spawn(config, None, Box::new(Constant(VOLTS)), 7);
    let link = SocketTransport::connect(ADDRESS, connector(port.connector()))
        .await
        .unwrap();
    (link, handle)
}

/// A connection attempt the meter's LAN port refuses, as a real meter's does while it is off.
pub fn refused() -> ConnectFuture {
    Box::pin(async {
        Err(LinkError::io(
            ADDRESS,
            "connecting",
            std::io::Error::from(std::io::ErrorKind::ConnectionRefused),
        ))
    })
}
