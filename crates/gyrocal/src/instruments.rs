//! Plan → instruments: the one place that knows which drivers exist.
//!
//! The engine is generic over one [`Bench`], which provides the instruments by role
//! ([`gyrocal_meter::Multimeter`], [`gyrocal_table::RateTable`]; room for a chamber and a
//! power supply); this module picks the concrete types from the plan, builds the bench and
//! hands it to one generic function, the way ripgrep's `crates/core/search.rs` dispatches
//! through `enum PatternMatcher` into a generic search. Adding a meter or a table dialect is a
//! new driver crate (or module) plus one arm here: [`with_meter`] for a meter,
//! [`with_table`] for a dialect. Each arm costs one monomorphised copy of the engine, so
//! arms are per meter *or* per table, never per pair.

use gyrocal_chamber::AnyChamber;
use gyrocal_files::plan::DmmModel;
use gyrocal_files::{Plan, TableDialect};
use gyrocal_hp34401a::{AutoZero, DcvConfig, DriverOptions, MeterTiming, Strategy};
use gyrocal_link::Transport;
use gyrocal_meter::{Multimeter, TimingModel};
use gyrocal_run::{Bench, MeterTableChamber};

/// The 34401A configuration a plan asks for.
pub fn hp34401a_config(plan: &Plan) -> DcvConfig {
    let d = plan.dmm();
    DcvConfig {
        range: Some(d.range_v),
        nplc: d.nplc,
        autozero: if d.autozero {
            AutoZero::On
        } else {
            AutoZero::Off
        },
        line_hz: d.line_hz,
        baud: d.baud,
        gpib: d.port.is_gpib(),
        ..DcvConfig::default()
    }
}

/// The 34401A strategy a plan's `acquisition` key names.
pub fn hp34401a_strategy(plan: &Plan) -> Strategy {
    match plan.dmm().acquisition {
        gyrocal_files::Acquisition::Auto => Strategy::Auto,
        gyrocal_files::Acquisition::Stream => Strategy::Stream,
        gyrocal_files::Acquisition::Memory => Strategy::Memory,
        gyrocal_files::Acquisition::Poll => Strategy::Poll,
    }
}

/// The Truevolt model a plan names, if it names one.
pub fn truevolt_model(plan: &Plan) -> Option<gyrocal_truevolt::Model> {
    match plan.dmm().model {
        DmmModel::Hp34401a => None,
        DmmModel::K34460a => Some(gyrocal_truevolt::Model::M34460A),
        DmmModel::K34461a => Some(gyrocal_truevolt::Model::M34461A),
        DmmModel::K34465a => Some(gyrocal_truevolt::Model::M34465A),
        DmmModel::K34470a => Some(gyrocal_truevolt::Model::M34470A),
    }
}

/// The DC-volts settings the plan asks of any meter.
pub fn dc_volts(plan: &Plan) -> gyrocal_meter::DcVolts {
    let d = plan.dmm();
    gyrocal_meter::DcVolts {
        range_v: Some(d.range_v),
        nplc: d.nplc,
        autozero: d.autozero,
        line_hz: d.line_hz,
    }
}

/// The Truevolt options a plan asks for (`acquisition`: `auto` and `stream` stream, `memory`
/// is memory; `poll` is refused by the plan's own validation).
pub fn truevolt_options(
    model: gyrocal_truevolt::Model,
    plan: &Plan,
) -> gyrocal_truevolt::TruevoltOptions {
    let acquisition = match plan.dmm().acquisition {
        gyrocal_files::Acquisition::Memory => gyrocal_truevolt::Acquisition::Memory,
        gyrocal_files::Acquisition::Stream => gyrocal_truevolt::Acquisition::Stream,
        _ => gyrocal_truevolt::Acquisition::Auto,
    };
    gyrocal_truevolt::TruevoltOptions {
        acquisition,
        ..gyrocal_truevolt::TruevoltOptions::new(model)
    }
}

/// The meter's timing model at the plan's settings, for an estimate before any instrument is
/// connected (`gyrocal check`).
pub fn meter_timing(plan: &Plan) -> Box<dyn TimingModel> {
    match truevolt_model(plan) {
        None => Box::new(MeterTiming::new(
            &hp34401a_config(plan),
            hp34401a_strategy(plan),
        )),
        Some(model) => Box::new(truevolt_options(model, plan).timing_at(&dc_volts(plan))),
    }
}

/// The table's client-side limits: the plan's.
pub fn table_limits(plan: &Plan) -> gyrocal_table::Limits {
    gyrocal_table::Limits {
        max_rate: plan.table().max_rate_dps,
        max_acceleration: plan.table().acceleration_dps2,
    }
}

/// What to do with the bench once it is built: a generic function over the [`Bench`] (the
/// engine with signals and progress, in `gyrocal run`). A further role (a chamber) adds an
/// associated type to the bench, not a type parameter here.
pub trait WithInstruments {
    /// What it returns.
    type Output;
    /// Runs on the bench.
    fn call<B>(self, bench: B) -> impl Future<Output = Self::Output>
    where
        B: Bench + 'static;
}

/// Builds the plan's multimeter on `dmm_link` and its table on `table_link` into a bench
/// ([`MeterTableChamber`], with `chamber`: the plan's, built by [`crate::chamber`], or none),
/// and hands it to `job`. The chamber is one run-time type ([`AnyChamber`]), so the engine is
/// still one copy per meter and per table, not per chamber too. A plan without a table (`[drift] table = "none"`) gets
/// [`gyrocal_table::NoTable`] whatever link is given (this is the one place that decides it);
/// a caller on instruments passes `None` for it, so no table port is opened.
pub async fn with_instruments<D, L, J>(
    plan: &Plan,
    dmm_link: D,
    table_link: Option<L>,
    chamber: AnyChamber,
    job: J,
) -> J::Output
where
    D: Transport + 'static,
    L: Transport + 'static,
    J: WithInstruments,
{
    with_meter(plan, dmm_link, table_link, chamber, job).await
}

/// The meter arm: one per multimeter model family.
async fn with_meter<D, L, J>(
    plan: &Plan,
    dmm_link: D,
    table_link: Option<L>,
    chamber: AnyChamber,
    job: J,
) -> J::Output
where
    D: Transport + 'static,
    L: Transport + 'static,
    J: WithInstruments,
{
    match truevolt_model(plan) {
        None => {
            let dmm = gyrocal_hp34401a::Hp34401aMeter::new(
                dmm_link,
                DriverOptions::default(),
                hp34401a_strategy(plan),
                plan.dmm().baud,
            )
            .over_gpib(plan.dmm().port.is_gpib());
            with_table(plan, dmm, table_link, chamber, job).await
        }
        Some(model) => {
            let dmm = gyrocal_truevolt::TruevoltMeter::new(dmm_link, truevolt_options(model, plan));
            with_table(plan, dmm, table_link, chamber, job).await
        }
    }
}

/// The table arm: one per dialect.
async fn with_table<M, L, J>(
    plan: &Plan,
    dmm: M,
    table_link: Option<L>,
    chamber: AnyChamber,
    job: J,
) -> J::Output
where
    M: Multimeter + 'static,
    L: Transport + 'static,
    J: WithInstruments,
{
    let Some(table_link) = table_link.filter(|_| plan.has_table()) else {
        return job
            .call(MeterTableChamber::new(
                dmm,
                gyrocal_table::NoTable::new(),
                chamber,
            ))
            .await;
    };
    let policy = gyrocal_table::PolicyConfig {
        limits: table_limits(plan),
        ..gyrocal_table::PolicyConfig::default()
    };
    match plan.table().dialect {
        TableDialect::Acl => {
            let config = gyrocal_acl::AclConfig {
                limits: policy.limits,
                ..gyrocal_acl::AclConfig::default()
            };
            let table = gyrocal_acl::AclTable::new(table_link, config);
            job.call(MeterTableChamber::new(dmm, table, chamber)).await
        }
        TableDialect::Aerosmith => {
            let config = gyrocal_aerosmith::AerosmithConfig {
                policy,
                ..gyrocal_aerosmith::AerosmithConfig::default()
            };
            let table = gyrocal_aerosmith::AerosmithTable::new(table_link, config);
            job.call(MeterTableChamber::new(dmm, table, chamber)).await
        }
    }
}

/// What the probe learnt from the table's driver.
#[derive(Debug, Clone)]
pub struct TableAnswer {
    /// The identity it gave.
    pub identity: gyrocal_table::Identity,
    /// Its mode, read after the identity.
    pub mode: gyrocal_table::TableMode,
    /// Its measured rate, °/s.
    pub rate_dps: f64,
}

/// Why the table's driver did not complete the probe: it did not identify the table
/// (`identity` is `None`), or it did and a read that followed failed.
#[derive(Debug, Clone)]
pub struct TableRefusal {
    /// The identity, when the driver got that far.
    pub identity: Option<gyrocal_table::Identity>,
    /// The driver's error, or "no answer within ..." when the time ran out.
    pub error: String,
}

/// Builds the plan's multimeter on `link` alone, connects it (identified, reset: nothing
/// measured) within `timeout` and gives it back to its front panel. The probe's meter half:
/// it runs whatever the table's port does.
pub async fn identify_meter<D>(
    plan: &Plan,
    link: D,
    timeout: std::time::Duration,
) -> Result<gyrocal_meter::Identity, String>
where
    D: Transport + 'static,
{
    async fn connect<M: Multimeter>(
        mut m: M,
        timeout: std::time::Duration,
    ) -> Result<gyrocal_meter::Identity, String> {
        let id = match tokio::time::timeout(timeout, m.connect()).await {
            Ok(Ok(id)) => id,
            Ok(Err(e)) => return Err(e.to_string()),
            Err(_) => return Err(format!("no answer within {} s", timeout.as_secs())),
        };
        let _ = tokio::time::timeout(timeout, m.release()).await;
        Ok(id)
    }
    match truevolt_model(plan) {
        None => {
            let m = gyrocal_hp34401a::Hp34401aMeter::new(
                link,
                DriverOptions::default(),
                hp34401a_strategy(plan),
                plan.dmm().baud,
            )
            .over_gpib(plan.dmm().port.is_gpib());
            connect(m, timeout).await
        }
        Some(model) => {
            connect(
                gyrocal_truevolt::TruevoltMeter::new(link, truevolt_options(model, plan)),
                timeout,
            )
            .await
        }
    }
}

/// Builds the plan's table on `link` alone (its dialect), identifies it and reads its mode and
/// rate, within `timeout` each; nothing moves. The probe's table half.
pub async fn identify_table<L>(
    plan: &Plan,
    link: L,
    timeout: std::time::Duration,
) -> Result<TableAnswer, TableRefusal>
where
    L: Transport + 'static,
{
    async fn ask<T: gyrocal_table::RateTable>(
        mut t: T,
        timeout: std::time::Duration,
    ) -> Result<TableAnswer, TableRefusal> {
        let late = || format!("no answer within {} s", timeout.as_secs());
        let identity = match tokio::time::timeout(timeout, t.connect()).await {
            Ok(Ok(id)) => id,
            Ok(Err(e)) => {
                return Err(TableRefusal {
                    identity: None,
                    error: e.to_string(),
                });
            }
            Err(_) => {
                return Err(TableRefusal {
                    identity: None,
                    error: late(),
                });
            }
        };
        let refused = |error: String| TableRefusal {
            identity: Some(identity.clone()),
            error,
        };
        let rate = match tokio::time::timeout(timeout, t.read_rate()).await {
            Ok(Ok(r)) => r,
            Ok(Err(e)) => return Err(refused(e.to_string())),
            Err(_) => return Err(refused(late())),
        };
        let status = match tokio::time::timeout(timeout, t.status()).await {
            Ok(Ok(s)) => s,
            Ok(Err(e)) => return Err(refused(e.to_string())),
            Err(_) => return Err(refused(late())),
        };
        Ok(TableAnswer {
            identity,
            mode: status.mode,
            rate_dps: rate,
        })
    }
    match plan.table().dialect {
        TableDialect::Acl => {
            let config = gyrocal_acl::AclConfig {
                limits: table_limits(plan),
                ..gyrocal_acl::AclConfig::default()
            };
            ask(gyrocal_acl::AclTable::new(link, config), timeout).await
        }
        TableDialect::Aerosmith => {
            let config = gyrocal_aerosmith::AerosmithConfig {
                policy: gyrocal_table::PolicyConfig {
                    limits: table_limits(plan),
                    ..gyrocal_table::PolicyConfig::default()
                },
                ..gyrocal_aerosmith::AerosmithConfig::default()
            };
            ask(
                gyrocal_aerosmith::AerosmithTable::new(link, config),
                timeout,
            )
            .await
        }
    }
}
