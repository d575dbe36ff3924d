//! The connection probe: open each instrument the plan names, identify it (the meter's error
//! queue is read as it connects), read the table's mode and rate, and give each back to its
//! front panel. `gyrocal check PLAN --probe` runs it alone; `gyrocal run` runs it before it
//! creates anything on disk, so an instrument that does not answer leaves no run directory.
//! A silent instrument gets the likely causes for its link.

use std::time::Duration;

use gyrocal_files::{Plan, Port};
use gyrocal_link::LinkOptions;
use gyrocal_meter::Multimeter;
use gyrocal_table::RateTable;

/// How long each instrument may take to identify itself.
const PROBE_TIMEOUT: Duration = Duration::from_secs(10);

/// What the probe found.
#[derive(Debug, Clone)]
pub struct Found {
    /// The multimeter's identity.
    pub dmm: String,
    /// The table's identity.
    pub table: String,
    /// The table's mode.
    pub table_mode: String,
    /// The table's measured rate, °/s.
    pub table_rate_dps: f64,
}

/// The options the plan's `[dmm]` port opens with.
pub fn dmm_link_options(plan: &Plan) -> LinkOptions {
    let d = plan.dmm();
    LinkOptions {
        baud: d.baud,
        framing: d.framing,
        // a Truevolt's tcp:// port is its SCPI socket (device clear reconnects); a 34401A's
        // is a serial converter
        scpi_socket: d.scpi_socket(),
        ..LinkOptions::default()
    }
}

/// The options the plan's `[table]` port opens with.
pub fn table_link_options(plan: &Plan) -> LinkOptions {
    LinkOptions {
        baud: plan.table().baud,
        ..LinkOptions::default()
    }
}

/// Opens both links, builds the instruments and probes them; `Err` says which instrument
/// did not answer and what to check on its link.
pub async fn probe(plan: &Plan) -> anyhow::Result<Found> {
    use anyhow::Context as _;
    let d = plan.dmm();
    let dmm = gyrocal_link::open_port(&d.port, &dmm_link_options(plan))
        .await
        .with_context(|| format!("opening the multimeter at {}", d.port))?;
    let t = plan.table();
    let table = if plan.has_table() {
        Some(
            gyrocal_link::open_port(&t.port, &table_link_options(plan))
                .await
                .with_context(|| format!("opening the rate table at {}", t.port))?,
        )
    } else {
        None
    };
    crate::instruments::with_instruments(plan, dmm, table, Probe { plan: plan.clone() })
        .await
        .map_err(|e| anyhow::anyhow!(e))
}

struct Probe {
    plan: Plan,
}

impl crate::instruments::WithInstruments for Probe {
    type Output = Result<Found, String>;

    async fn call<B>(self, mut bench: B) -> Self::Output
    where
        B: gyrocal_run::Bench + 'static,
    {
        let (dmm, table) = bench.meter_and_table();
        let d = self.plan.dmm();
        let id = match tokio::time::timeout(PROBE_TIMEOUT, dmm.connect()).await {
            Ok(Ok(id)) => id,
            Ok(Err(e)) => return Err(silent("multimeter", &d.port, &e.to_string(), &self.plan)),
            Err(_) => return Err(silent("multimeter", &d.port, "no answer", &self.plan)),
        };
        let _ = tokio::time::timeout(PROBE_TIMEOUT, dmm.release()).await;
        if !self.plan.has_table() {
            return Ok(Found {
                dmm: id.raw,
                table: gyrocal_table::NO_TABLE.into(),
                table_mode: "none".into(),
                table_rate_dps: 0.0,
            });
        }
        let t = self.plan.table();
        let tid = match tokio::time::timeout(PROBE_TIMEOUT, table.connect()).await {
            Ok(Ok(id)) => id,
            Ok(Err(e)) => return Err(silent("rate table", &t.port, &e.to_string(), &self.plan)),
            Err(_) => return Err(silent("rate table", &t.port, "no answer", &self.plan)),
        };
        let rate = table
            .read_rate()
            .await
            .map_err(|e| silent("rate table", &t.port, &e.to_string(), &self.plan))?;
        let status = table
            .status()
            .await
            .map_err(|e| silent("rate table", &t.port, &e.to_string(), &self.plan))?;
        Ok(Found {
            dmm: id.raw,
            table: format!(
                "{},{},{},{}",
                tid.manufacturer, tid.model, tid.serial, tid.version
            ),
            table_mode: format!("{:?}", status.mode),
            table_rate_dps: rate,
        })
    }
}

/// "the multimeter at PORT did not answer (why): check ..." with the causes its link makes
/// likely.
fn silent(what: &str, port: &Port, why: &str, plan: &Plan) -> String {
    let causes = match port {
        Port::Serial(_) if what == "multimeter" => format!(
            "check that it is on, that its RS-232 settings (front panel I/O MENU) are {} baud and \
             {} as the plan says, that the cable is a null-modem one, and that no other program \
             holds the port",
            plan.dmm().baud,
            plan.dmm().framing
        ),
        Port::Serial(_) => format!(
            "check that the controller is on and set to {} baud, the cable, and that no other \
             program holds the port",
            plan.table().baud
        ),
        Port::PrologixSerial { .. } | Port::PrologixTcp { .. } => {
            "check the GPIB address (the port's addr=N against the meter's HP-IB \
                          address), that the Prologix controller is connected and powered, and \
                          the GPIB cable"
                .to_string()
        }
        Port::Tcp { host, port } => format!(
            "check that {host} is reachable and listens on port {port} (a Truevolt's SCPI \
             socket is 5025), that the instrument's LAN interface is enabled, and that no \
             other client holds the socket"
        ),
    };
    format!("the {what} at {port} did not answer ({why}): {causes}")
}
