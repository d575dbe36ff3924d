//! What the ACL driver's tests share (`mod common;`): the table's empty error queue as it
//! answers it, and the simulated table on an in-memory pipe with the driver connected and
//! enabled (servo on), from which the simulator tests start.

#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)] // each test file uses a subset

use std::time::Duration;

use gyrocal_acl::{AclConfig, AclTable};
use gyrocal_link::memory_pair;
use gyrocal_sim::table::{SimTable, TableConfig, TableHandle};
use gyrocal_table::RateTable;

/// The ACL controller's answer to `:System:Error?` when its error queue is empty.
pub const NO_ERROR: &str = "0,\"No error\"";

/// The driver on the simulated table's in-memory pipe.
pub type Table = AclTable<gyrocal_link::StreamTransport<tokio::io::DuplexStream>>;

/// A simulated table (`config`, its noise drawn from `seed`) on an in-memory pipe named
/// `sim-table`, and the driver on it with the default options, connected and enabled.
pub async fn enabled_sim_table(config: TableConfig, seed: u64) -> (Table, TableHandle) {
    let (transport, device) = memory_pair("sim-table");
    let handle = SimTable::spawn(device, config, seed);
    let mut table = AclTable::new(transport, AclConfig::default());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    (table, handle)
}

/// Commands have no reply: let the simulator task read what was written before looking at it.
pub async fn let_sim_run() {
    tokio::time::sleep(Duration::from_millis(1)).await;
}
