//! The plan → instrument choice for the tests and the bench (the CLI's `instruments` module
//! does this for runs; the library itself knows no driver).

#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use gyrocal_acl::AclConfig;
use gyrocal_files::{Acquisition, Plan, RunDir, RunMeta};
use gyrocal_hp34401a::{DriverOptions, Hp34401aMeter, Strategy};
use gyrocal_link::Transport;

/// The plans written once for every crate's tests.
#[path = "../../../../tests/support/plans.rs"]
pub mod plans;

/// A file under `configs/`.
pub fn config(name: &str) -> PathBuf {
    plans::config(name)
}

/// The shipped plan `configs/NAME` with `edit` applied to its TOML document (use [`set`]).
pub fn plan_with(name: &str, edit: impl FnOnce(&mut toml::Table)) -> Plan {
    let path = config(name);
    let mut doc: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    edit(&mut doc);
    Plan::from_toml_str(&toml::to_string(&doc).unwrap(), &path).unwrap()
}

/// Sets `key` of `[section]` (which the document must have) to `value`.
pub fn set(doc: &mut toml::Table, section: &str, key: &str, value: toml::Value) {
    doc.get_mut(section)
        .unwrap()
        .as_table_mut()
        .unwrap()
        .insert(key.into(), value);
}

/// A shipped plan with other rates.
pub fn plan_from(name: &str, rates: &[f64]) -> Plan {
    plan_with(name, |d| {
        let rates = rates.iter().map(|r| toml::Value::Float(*r)).collect();
        set(d, "plan", "rates_dps", toml::Value::Array(rates));
    })
}

/// quick.toml with other rates.
pub fn plan_with_rates(rates: &[f64]) -> Plan {
    plan_from("quick.toml", rates)
}

/// A fresh run directory of a simulated run.
pub fn new_run(plan: &Plan, dir: &Path) -> RunDir {
    let meta = RunMeta {
        gyrocal_version: "test".into(),
        simulated: true,
        ..RunMeta::default()
    };
    RunDir::create(dir, plan, meta).unwrap()
}

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
