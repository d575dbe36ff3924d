//! The thermal chamber of a temperature series, built from the plan's `[chamber]` section: the
//! one place that maps the plan's keys onto a driver's settings, for a real controller (a
//! serial port or a Modbus TCP address) and for the simulated bench's in-memory link.
//!
//! Why here and not in the plan crate: the plan crate builds without any driver (it is read
//! by the report and the analysis, which have no I/O); the binary is the one crate that knows
//! both the plan and the drivers, as `instruments.rs` does for the meter and the table.

use anyhow::Context;
use gyrocal_chamber::{
    AlarmRegister, AnyChamber, Espec, EspecConfig, NoChamber, ProductInput, WatlowConfig, WatlowF4,
};
use gyrocal_files::Plan;
use gyrocal_files::plan::{ChamberModel, ChamberSettings};
use gyrocal_link::{Link, LinkOptions, PortSpec};

/// The Watlow F4 driver's settings from `[chamber]`: the slave, the product input, the plan's
/// limits (narrowed again at connect by the controller's own range), the alarm registers and
/// the "chamber on" output; the rest (timeouts, retries) the driver's defaults.
pub fn watlow_config(c: &ChamberSettings) -> WatlowConfig {
    WatlowConfig {
        slave: c.slave,
        product_input: match c.product_input {
            3 => ProductInput::Input3,
            _ => ProductInput::Input2,
        },
        min_c: c.min_c,
        max_c: c.max_c,
        alarms: c
            .alarm_registers
            .iter()
            .map(|a| AlarmRegister {
                register: a.register,
                mask: a.mask,
                active: a.active,
                name: a.name.clone(),
            })
            .collect(),
        chamber_on_output: c.chamber_on_output,
        ..WatlowConfig::default()
    }
}

/// The Espec driver's settings from `[chamber]`: the plan's limits and baud; the unconfirmed
/// options (mode and alarm queries) at the driver's documented defaults.
pub fn espec_config(c: &ChamberSettings) -> EspecConfig {
    EspecConfig {
        min_c: c.min_c,
        max_c: c.max_c,
        baud: c.baud,
        ..EspecConfig::default()
    }
}

/// The chamber of a run on real instruments: none when the plan has no `[chamber]`; otherwise
/// its port opened (a serial port for Modbus RTU or the Espec's text, `tcp://HOST:PORT` for
/// Modbus TCP). Opened before the run directory is created, like the meter's and the table's
/// ports, so a chamber that is not there leaves nothing behind. `port` overrides the plan's
/// (`gyrocal run --chamber-port`).
pub async fn open(plan: &Plan, port: Option<&str>) -> anyhow::Result<AnyChamber> {
    let Some(c) = plan.chamber() else {
        return Ok(AnyChamber::from(NoChamber));
    };
    let spec = match port {
        Some(p) => p
            .parse::<PortSpec>()
            .map_err(|e| anyhow::anyhow!("--chamber-port {p}: {e}"))?,
        None => c.port.clone(),
    };
    open_spec(c, &spec).await
}

async fn open_spec(c: &ChamberSettings, spec: &PortSpec) -> anyhow::Result<AnyChamber> {
    let what = || format!("opening the chamber ({}) at {spec}", c.model.as_str());
    match (c.model, spec) {
        (ChamberModel::WatlowF4, PortSpec::Tcp { host, port }) => {
            let addr = format!("{host}:{port}");
            let chamber = WatlowF4::connect_tcp(&addr, watlow_config(c))
                .await
                .with_context(what)?;
            Ok(chamber.into())
        }
        (ChamberModel::WatlowF4, PortSpec::Serial(path)) => {
            let chamber = WatlowF4::open_rtu(&path.to_string_lossy(), c.baud, watlow_config(c))
                .with_context(what)?;
            Ok(chamber.into())
        }
        (ChamberModel::Espec, PortSpec::Serial(_) | PortSpec::Tcp { .. }) => {
            let options = LinkOptions {
                baud: c.baud,
                ..LinkOptions::default()
            };
            let link = gyrocal_link::open_port(spec, &options)
                .await
                .with_context(what)?;
            let chamber = Espec::over_transport(link, espec_config(c)).with_context(what)?;
            Ok(chamber.into())
        }
        (_, other) => anyhow::bail!(
            "[chamber] port = \"{other}\": a {} is reached over a serial port or tcp://HOST:PORT",
            c.model.as_str()
        ),
    }
}

/// The chamber of a simulated run: the real driver over the simulated bench's in-memory
/// link (`link`, from `gyrocal_sim::bench::Bench::chamber_link`), so the run drives the same
/// code as on a real chamber. None when the plan has no `[chamber]`.
pub fn simulated(plan: &Plan, link: Option<tokio::io::DuplexStream>) -> anyhow::Result<AnyChamber> {
    let Some(c) = plan.chamber() else {
        return Ok(AnyChamber::from(NoChamber));
    };
    let Some(stream) = link else {
        anyhow::bail!("the simulated bench has no chamber for the plan's [chamber]");
    };
    match c.model {
        ChamberModel::WatlowF4 => {
            Ok(WatlowF4::over_stream(stream, "sim-chamber", c.baud, watlow_config(c))?.into())
        }
        ChamberModel::Espec => {
            let transport = gyrocal_link::StreamTransport::new(stream, "sim-chamber");
            let link = Link::Stream(transport.boxed());
            Ok(Espec::over_transport(link, espec_config(c))?.into())
        }
    }
}
