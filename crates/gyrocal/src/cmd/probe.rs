//! The connection probe: open each instrument's port the plan names, identify the instrument
//! there (the meter's error queue is read as it connects), read the table's mode and rate, and
//! give each back to its front panel. `gyrocal check PLAN --probe` runs it alone; `gyrocal run`
//! runs it before it creates anything on disk, so an instrument that does not answer leaves
//! no run directory.
//!
//! Both ports are always probed, at the same time: a failure on one does not hide the other.
//! A port whose driver fails gets a second look ([`answer::look`]) that says who answers
//! there, so swapped cables read "the ports look swapped ... swap them" rather than "the
//! multimeter did not answer" with cable advice; the likely causes for a link (baud, cable,
//! address) are given only when no instrument answered at all.
//!
//! A plan with a `[chamber]` (a temperature series) has its chamber probed too, at the same
//! time ([`chamber`]): identified and read, nothing written.

mod answer;
pub mod chamber;

use std::time::Duration;

use gyrocal_files::{Plan, Port};
use gyrocal_link::LinkOptions;

pub use answer::{Who, classify};

/// How long each instrument may take to identify itself.
const PROBE_TIMEOUT: Duration = Duration::from_secs(10);

/// Which ports were given on the command line (`--dmm-port`, `--table-port`) rather than
/// taken from the plan: messages name them the way the user gave them.
#[derive(Debug, Clone, Copy, Default)]
pub struct PortFlags {
    /// `--dmm-port` was given.
    pub dmm: bool,
    /// `--table-port` was given.
    pub table: bool,
}

/// What the probe found.
#[derive(Debug, Clone)]
pub struct Found {
    /// The multimeter's identity, as it answered.
    pub dmm: String,
    /// The multimeter's identity, parsed (its serial field is compared with the station's).
    pub dmm_identity: gyrocal_meter::Identity,
    /// The table's identity, in words.
    pub table: String,
    /// The table's identity, parsed (`None`: the plan drives no table).
    pub table_identity: Option<gyrocal_table::Identity>,
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

/// What went wrong, by kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProbeErrorKind {
    /// The multimeter answered on the table's port and the table on the multimeter's.
    Swapped,
    /// One instrument answered on the other's port.
    WrongPort,
    /// An instrument answered on its own port but its driver refused it (another model or
    /// dialect than the plan says), or a read after its identity failed.
    Refused,
    /// No instrument answered on a port (or it did not open).
    NotAnswered,
}

/// One port as the probe saw it.
#[derive(Debug, Clone)]
pub struct PortReport {
    /// The port.
    pub port: Port,
    /// How the user named it: `--dmm-port` or `the plan's [dmm] port`.
    pub named: &'static str,
    /// Why its instrument was not accepted (`None`: it answered and its driver accepted it).
    pub failure: Option<Failure>,
    /// Who answered there, when the driver failed.
    pub who: Option<Who>,
}

impl PortReport {
    /// "--dmm-port /dev/ttyUSB0".
    pub fn name(&self) -> String {
        format!("{} {}", self.named, self.port)
    }
}

/// The probe's failure: what each port answered, and what it means.
#[derive(Debug, Clone)]
pub struct ProbeError {
    kind: ProbeErrorKind,
    headline: String,
    /// The multimeter's port.
    pub dmm: PortReport,
    /// The table's port (`None`: the plan drives no table).
    pub table: Option<PortReport>,
}

impl ProbeError {
    /// The kind of failure.
    pub fn kind(&self) -> ProbeErrorKind {
        self.kind
    }

    /// The diagnosis alone, without the per-port lines.
    pub fn headline(&self) -> &str {
        &self.headline
    }
}

impl ProbeError {
    /// Each port in the `--json` document: its name, who answered there (`multimeter`,
    /// `table`, `other`, `nothing`, `unopened`, or `expected` when its instrument answered
    /// and was accepted) and what it sent.
    pub fn ports_json(&self) -> serde_json::Value {
        let one = |p: &PortReport| {
            serde_json::json!({
                "port": p.port.to_string(),
                "named": p.named,
                "answered": p.who.as_ref().map_or("expected", Who::key),
                "reply": p.who.as_ref().and_then(Who::reply),
            })
        };
        serde_json::json!({
            "dmm": one(&self.dmm),
            "table": self.table.as_ref().map(one),
        })
    }
}

impl std::fmt::Display for ProbeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.headline)?;
        let ports = std::iter::once(("multimeter", &self.dmm))
            .chain(self.table.as_ref().map(|t| ("rate table", t)));
        for (role, p) in ports {
            write!(f, "; the {role}'s port ({}): ", p.name())?;
            match &p.who {
                None => write!(f, "the {role} answers")?,
                Some(who) => write!(f, "{}", who.words())?,
            }
        }
        Ok(())
    }
}

impl std::error::Error for ProbeError {}

/// Opens both links, builds each instrument on its own link and probes both at the same
/// time; `Err` is a [`ProbeError`] that says what answered on each port and what to do.
pub async fn probe(plan: &Plan, flags: PortFlags) -> anyhow::Result<Found> {
    let d = plan.dmm();
    let t = plan.table();
    let has_table = plan.has_table();
    let meter_half = async {
        match gyrocal_link::open_port(&d.port, &dmm_link_options(plan)).await {
            Ok(link) => Ok(crate::instruments::identify_meter(plan, link, PROBE_TIMEOUT).await),
            Err(e) => Err(e),
        }
    };
    let table_half = async {
        if !has_table {
            return None;
        }
        Some(
            match gyrocal_link::open_port(&t.port, &table_link_options(plan)).await {
                Ok(link) => Ok(crate::instruments::identify_table(plan, link, PROBE_TIMEOUT).await),
                Err(e) => Err(e),
            },
        )
    };
    let (meter, table) = tokio::join!(meter_half, table_half);

    // the driver's verdict on each port: `None` when it accepted its instrument
    let meter_error = match &meter {
        Ok(Ok(_)) => None,
        Ok(Err(e)) => Some(Failure::Driver(e.clone())),
        Err(e) => Some(Failure::Open(OpenFailure::of(e))),
    };
    let table_error = match &table {
        None => None,
        Some(Ok(Ok(a))) => {
            // a driver that takes any four-field identity (ACL) may have accepted a meter's
            let said = format!(
                "{},{},{},{}",
                a.identity.manufacturer, a.identity.model, a.identity.serial, a.identity.version
            );
            matches!(classify(&said), Who::Meter { .. })
                .then(|| Failure::Driver(format!("it identified as {said}, a multimeter")))
        }
        Some(Ok(Err(r))) => Some(Failure::Driver(match &r.identity {
            Some(id) => format!(
                "it identified as {},{},{},{}, then: {}",
                id.manufacturer, id.model, id.serial, id.version, r.error
            ),
            None => r.error.clone(),
        })),
        Some(Err(e)) => Some(Failure::Open(OpenFailure::of(e))),
    };
    if meter_error.is_none()
        && table_error.is_none()
        && let Ok(Ok(id)) = meter
    {
        let answer = match table {
            Some(Ok(Ok(a))) => Some(a),
            _ => None,
        };
        return Ok(found(id, answer));
    }

    // a second look at each port whose driver failed: who answers there?
    let look = |port: &Port, options: LinkOptions, failure: Option<&Failure>| {
        let port = port.clone();
        let failure = failure.cloned();
        async move {
            match failure? {
                Failure::Open(o) => Some(Who::Unopened { error: o.text }),
                Failure::Driver(_) => Some(match gyrocal_link::open_port(&port, &options).await {
                    Ok(mut link) => answer::look(&mut link).await,
                    Err(e) => Who::Unopened {
                        error: e.to_string(),
                    },
                }),
            }
        }
    };
    let (dmm_who, table_who) = tokio::join!(
        look(&d.port, dmm_link_options(plan), meter_error.as_ref()),
        look(&t.port, table_link_options(plan), table_error.as_ref()),
    );
    let dmm = PortReport {
        port: d.port.clone(),
        named: if flags.dmm {
            "--dmm-port"
        } else {
            "the plan's [dmm] port"
        },
        failure: meter_error,
        who: dmm_who,
    };
    let table = has_table.then(|| PortReport {
        port: t.port.clone(),
        named: if flags.table {
            "--table-port"
        } else {
            "the plan's [table] port"
        },
        failure: table_error,
        who: table_who,
    });
    Err(diagnose(plan, dmm, table).into())
}

/// Why a port's instrument was not accepted.
#[derive(Debug, Clone)]
pub enum Failure {
    /// The port did not open.
    Open(OpenFailure),
    /// The driver's error.
    Driver(String),
}

/// A port that did not open: the whole message, and its cause alone (said once when both
/// ports fail the same way).
#[derive(Debug, Clone)]
pub struct OpenFailure {
    /// The link's message (it names the port).
    pub text: String,
    /// The operating system's cause alone.
    pub cause: String,
}

impl OpenFailure {
    fn of(e: &gyrocal_link::LinkError) -> OpenFailure {
        let cause = match e {
            gyrocal_link::LinkError::Io { source, .. } => source.to_string(),
            other => other.to_string(),
        };
        OpenFailure {
            text: e.to_string(),
            cause,
        }
    }
}

/// The station's serials against the identities the probe found (the table's only when the
/// plan drives one).
pub fn serial_checks(
    station: &gyrocal_files::station::Station,
    found: &Found,
) -> Vec<gyrocal_files::station::SerialCheck> {
    station.check_serials(
        Some(&found.dmm_identity.serial),
        found
            .table_identity
            .as_ref()
            .map(|t| Some(t.serial.as_str())),
    )
}

/// The found instruments in the probe's words.
fn found(id: gyrocal_meter::Identity, table: Option<crate::instruments::TableAnswer>) -> Found {
    match table {
        Some(a) => Found {
            dmm: id.raw.clone(),
            dmm_identity: id,
            table: format!(
                "{},{},{},{}",
                a.identity.manufacturer, a.identity.model, a.identity.serial, a.identity.version
            ),
            table_identity: Some(a.identity),
            table_mode: format!("{:?}", a.mode),
            table_rate_dps: a.rate_dps,
        },
        None => Found {
            dmm: id.raw.clone(),
            dmm_identity: id,
            table: gyrocal_table::NO_TABLE.into(),
            table_identity: None,
            table_mode: "none".into(),
            table_rate_dps: 0.0,
        },
    }
}

/// What the two ports' answers mean, said as the thing to do.
fn diagnose(plan: &Plan, dmm: PortReport, table: Option<PortReport>) -> ProbeError {
    let is =
        |p: Option<&PortReport>, f: fn(&Who) -> bool| p.and_then(|p| p.who.as_ref()).is_some_and(f);
    let meter_on_table_port = is(table.as_ref(), |w| matches!(w, Who::Meter { .. }));
    let table_on_meter_port = is(Some(&dmm), |w| matches!(w, Who::Table { .. }));
    let (kind, headline) = if meter_on_table_port && table_on_meter_port {
        let t = table.as_ref().map(PortReport::name).unwrap_or_default();
        (
            ProbeErrorKind::Swapped,
            format!(
                "the ports look swapped: the multimeter answered on {t} and the rate table on \
                 {}; swap them",
                dmm.name()
            ),
        )
    } else {
        // each port on its own: the other instrument there, the right one refused, nothing
        let mut parts = Vec::new();
        let mut kinds = Vec::new();
        let ports: Vec<(&str, &PortReport)> = std::iter::once(("multimeter", &dmm))
            .chain(table.iter().map(|t| ("rate table", t)))
            .collect();
        // two ports that did not open for the same reason: the reason once
        let unopened: Vec<(&str, &PortReport, &OpenFailure)> = ports
            .iter()
            .filter_map(|&(what, p)| match &p.failure {
                Some(Failure::Open(o)) => Some((what, p, o)),
                _ => None,
            })
            .collect();
        if let [(w1, p1, o1), (w2, p2, o2)] = unopened[..]
            && o1.cause == o2.cause
        {
            kinds.push(ProbeErrorKind::NotAnswered);
            parts.push(format!(
                "opening the {w1} at {} and the {w2} at {}: {}",
                p1.port, p2.port, o1.cause
            ));
        } else {
            for (what, p, o) in &unopened {
                kinds.push(ProbeErrorKind::NotAnswered);
                parts.push(format!("opening the {what} at {}: {}", p.port, o.text));
            }
        }
        for (what, p) in ports {
            let (Some(Failure::Driver(error)), Some(who)) = (&p.failure, &p.who) else {
                continue;
            };
            let other = match (what, who) {
                ("multimeter", Who::Table { .. }) => Some("a rate table"),
                ("rate table", Who::Meter { .. }) => Some("a multimeter"),
                _ => None,
            };
            if let Some(other) = other {
                kinds.push(ProbeErrorKind::WrongPort);
                parts.push(format!(
                    "{other} answered on the {what}'s port ({}), not the {what}: give the \
                     {what}'s port there",
                    p.name()
                ));
            } else if who.is_instrument() && error.starts_with("it identified as") {
                // its own driver knew it, then a read failed: not a question of model
                kinds.push(ProbeErrorKind::Refused);
                parts.push(format!(
                    "the {what} at {} identified itself but did not complete the probe \
                     ({error})",
                    p.port
                ));
            } else if who.is_instrument() {
                // the right instrument, refused by its driver: another model or dialect
                kinds.push(ProbeErrorKind::Refused);
                parts.push(format!(
                    "the {what} at {} answered but was not accepted ({error}): check the \
                     plan's model or dialect against the instrument",
                    p.port
                ));
            } else {
                kinds.push(ProbeErrorKind::NotAnswered);
                let why = match who {
                    Who::Other { reply } => format!("{error}; it sent {}", answer::quoted(reply)),
                    _ => error.clone(),
                };
                parts.push(silent(what, &p.port, &why, plan));
            }
        }
        // the kind of the first thing said (the most useful to act on comes first)
        let kind = kinds
            .iter()
            .copied()
            .find(|k| *k == ProbeErrorKind::WrongPort)
            .or_else(|| kinds.first().copied())
            .unwrap_or(ProbeErrorKind::NotAnswered);
        (kind, parts.join("; and "))
    };
    ProbeError {
        kind,
        headline,
        dmm,
        table,
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
