//! What the Aerosmith dialect's tests share (`mod common;`): the driver with its default
//! options on any link (a script or the simulated table), and the simulated table serving the
//! dialect on an in-memory pipe.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use gyrocal_aerosmith::{AerosmithConfig, AerosmithTable};
use gyrocal_link::{Transport, memory_pair};
use gyrocal_sim::table::aerosmith::AerosmithWire;
use gyrocal_sim::table::{SimTable, TableConfig, TableHandle};

/// The driver on the simulated table's in-memory pipe.
pub type Table = AerosmithTable<gyrocal_link::StreamTransport<tokio::io::DuplexStream>>;

/// The driver with the default options (the dialect's usual line ending, units and MCO
/// polarity) on `link`, not yet connected.
pub fn aerosmith<T: Transport + 'static>(link: T) -> AerosmithTable<T> {
    AerosmithTable::new(link, AerosmithConfig::default())
}

/// A simulated table (`config`, noise from `seed`) speaking the dialect with its default wire
/// settings on an in-memory pipe named `sim-aerosmith`, and the driver on it (not connected).
pub fn sim_aerosmith(config: TableConfig, seed: u64) -> (Table, TableHandle) {
    let (transport, device) = memory_pair("sim-aerosmith");
    let handle = SimTable::spawn_aerosmith(device, config, AerosmithWire::default(), seed);
    (aerosmith(transport), handle)
}
