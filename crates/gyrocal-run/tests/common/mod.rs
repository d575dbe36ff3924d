//! The plan → instrument choice for the tests and the bench (the CLI's `instruments` module
//! does this for runs; the library itself knows no driver).

#![allow(dead_code)]

use gyrocal_acl::AclConfig;
use gyrocal_hp34401a::{DriverOptions, Hp34401aMeter, Strategy};
use gyrocal_link::Transport;
use gyrocal_run::{Acquisition, Plan};

/// The 34401A on `link` as `plan` sets it up.
pub fn hp34401a<T: Transport + 'static>(link: T, plan: &Plan) -> Hp34401aMeter<T> {
    let strategy = match plan.dmm().acquisition {
        Acquisition::Auto => Strategy::Auto,
        Acquisition::Stream => Strategy::Stream,
        Acquisition::Memory => Strategy::Memory,
        Acquisition::Poll => Strategy::Poll,
    };
    Hp34401aMeter::new(link, DriverOptions::default(), strategy, plan.dmm().baud)
}

/// The ACL table configuration with the plan's limits.
pub fn table_config(plan: &Plan) -> AclConfig {
    AclConfig {
        limits: gyrocal_table::Limits {
            max_rate: plan.table().max_rate_dps,
            max_acceleration: plan.table().acceleration_dps2,
        },
        ..AclConfig::default()
    }
}
