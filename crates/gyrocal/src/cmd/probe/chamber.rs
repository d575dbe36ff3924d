//! The chamber's part of `gyrocal check --probe`, for a plan with a `[chamber]` (a
//! temperature series): open the controller's port, identify it (what the driver's `connect`
//! reads: the F4's units, decimal places and input range; the Espec's `TYPE?`), take one
//! reading (air and product temperature, setpoint, mode, alarms) and close it. Nothing is
//! written: `connect` and `read` are queries on every dialect, so a probe never changes a
//! chamber's setpoint or mode.
//!
//! Why a latched alarm fails the probe: a run reads the chamber before it moves anything and
//! stops at once on an alarm (gyrocal never resets one), so a probe that said "answers" would
//! send the operator to a run that cannot start. The reading is shown all the same.
//!
//! A controller that does not answer gets the meter's and the table's second look
//! ([`super::answer::look`]) on its port, so a multimeter's or a table's port given as the
//! chamber's is said as such, and a silent port is told from one where something else talks.

use std::time::Duration;

use gyrocal_chamber::{Chamber as _, ChamberErrorKind, ChamberReading};
use gyrocal_files::Plan;
use gyrocal_link::{LinkOptions, PortSpec};

use super::answer::{self, Who};

/// How long the chamber may take to be opened, identified and read (a silent F4 fails its
/// first read after 3 × 1 s; an Espec's replies may take seconds each).
const CHAMBER_PROBE_TIMEOUT: Duration = Duration::from_secs(60);

/// What the probe read from the chamber.
#[derive(Debug, Clone)]
pub struct ChamberFound {
    /// Its port, as the probe opened it.
    pub port: String,
    /// How the user named it: `--chamber-port` or `the plan's [chamber] port`.
    pub named: &'static str,
    /// The controller (`Watlow F4`, `Espec SH-641`).
    pub model: String,
    /// What it answered to identify itself.
    pub detail: String,
    /// One reading.
    pub reading: ChamberReading,
}

impl ChamberFound {
    /// The reading in words: "air 23.1 °C, gyro 23.0 °C, setpoint 23.0 °C, mode constant,
    /// no alarm".
    pub fn reading_words(&self) -> String {
        let r = &self.reading;
        let gyro = r
            .product_c
            .map_or("no gyro (product) input".to_string(), |t| {
                format!("gyro {t:.1} °C")
            });
        let alarms = if r.alarms.is_empty() {
            "no alarm".to_string()
        } else {
            format!("ALARM: {}", r.alarms.join(", "))
        };
        format!(
            "air {:.1} °C, {gyro}, setpoint {:.1} °C, mode {}, {alarms}",
            r.air_c, r.setpoint_c, r.mode
        )
    }

    /// The `--json` document's `probe.chamber`.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "answered": true,
            "port": self.port,
            "named": self.named,
            "model": self.model,
            "detail": self.detail,
            "air_c": self.reading.air_c,
            "product_c": self.reading.product_c,
            "setpoint_c": self.reading.setpoint_c,
            "mode": self.reading.mode,
            "alarms": self.reading.alarms,
        })
    }
}

/// Why the chamber's probe failed.
#[derive(Debug)]
pub struct ChamberProbeError {
    /// What to tell the operator.
    pub headline: String,
    /// Who answered on the port when the controller did not (`None`: not looked, or it did).
    pub who: Option<Who>,
    /// What it read, when it read (an alarm is latched).
    pub found: Option<ChamberFound>,
}

impl std::fmt::Display for ChamberProbeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.headline)
    }
}

impl std::error::Error for ChamberProbeError {}

impl ChamberProbeError {
    /// The `--json` document's `probe.chamber`.
    pub fn json(&self) -> serde_json::Value {
        let mut doc = match &self.found {
            Some(found) => found.json(),
            None => serde_json::json!({ "answered": false }),
        };
        doc["error"] = self.headline.clone().into();
        if let Some(who) = &self.who {
            doc["answered_by"] = who.key().into();
            doc["reply"] = who.reply().into();
        }
        doc
    }
}

/// Probes the plan's chamber (at `port` when given, `--chamber-port`); `None` when the plan
/// has no `[chamber]` (a sweep or a drift record: there is nothing to probe).
pub async fn probe(
    plan: &Plan,
    port: Option<&PortSpec>,
) -> Option<Result<ChamberFound, ChamberProbeError>> {
    let settings = plan.chamber()?;
    let spec = port.cloned().unwrap_or_else(|| settings.port.clone());
    let named = if port.is_some() {
        "--chamber-port"
    } else {
        "the plan's [chamber] port"
    };
    let model = settings.model.as_str();
    let port_words = format!("{named} {spec}");
    let outcome = tokio::time::timeout(CHAMBER_PROBE_TIMEOUT, identify_and_read(plan, &spec)).await;
    let step = match outcome {
        Ok(step) => step,
        Err(_) => Step::Silent(format!(
            "no answer within {} s",
            CHAMBER_PROBE_TIMEOUT.as_secs()
        )),
    };
    Some(match step {
        Step::Read(found) => {
            let found = ChamberFound {
                port: spec.to_string(),
                named,
                ..found
            };
            if found.reading.alarms.is_empty() {
                Ok(found)
            } else {
                Err(ChamberProbeError {
                    headline: format!(
                        "chamber alarm: {} latched on the chamber ({model}) at {port_words}: a run \
                         stops at its first reading of the chamber while it is; it must be \
                         cleared at the chamber (gyrocal never resets an alarm)",
                        found.reading.alarms.join(", ")
                    ),
                    who: None,
                    found: Some(found),
                })
            }
        }
        Step::Unopened(e) => Err(ChamberProbeError {
            headline: format!("the chamber ({model}) at {port_words} did not open: {e}"),
            who: None,
            found: None,
        }),
        Step::Refused(e) => Err(ChamberProbeError {
            headline: format!(
                "the chamber ({model}) at {port_words} answered but was not accepted: {e}"
            ),
            who: None,
            found: None,
        }),
        Step::Unread(model_said, e) => Err(ChamberProbeError {
            headline: format!(
                "the chamber at {port_words} identified itself ({model_said}) but its reading \
                 failed: {e}"
            ),
            who: None,
            found: None,
        }),
        Step::Silent(e) => {
            let who = second_look(&spec, settings.baud).await;
            let what = match &who {
                Who::Nothing => format!(
                    "nothing answered there: {}",
                    causes(&spec, settings.baud, settings.slave)
                ),
                Who::Unopened { error } => format!("the port did not open again: {error}"),
                Who::Meter { .. } | Who::Table { .. } => {
                    format!("{} there: give the chamber's own port", who.words())
                }
                Who::Other { reply } => format!(
                    "something else talks there, {} (another device, or the controller at \
                     another baud rate or protocol)",
                    answer::quoted(reply)
                ),
            };
            Err(ChamberProbeError {
                headline: format!(
                    "the chamber ({model}) at {port_words} did not answer ({e}); {what}"
                ),
                who: Some(who),
                found: None,
            })
        }
    })
}

/// How far the probe got.
enum Step {
    /// The port did not open.
    Unopened(String),
    /// Nothing (or nothing valid) answered the identification.
    Silent(String),
    /// The controller answered and its driver refused it (°F, an exception, a bad setting).
    Refused(String),
    /// Identified (the model said), then the reading failed.
    Unread(String, String),
    /// Identified and read (the port and how it was named filled in by the caller).
    Read(ChamberFound),
}

async fn identify_and_read(plan: &Plan, spec: &PortSpec) -> Step {
    let port = spec.to_string();
    let mut chamber = match crate::chamber::open(plan, Some(&port)).await {
        Ok(c) => c,
        Err(e) => return Step::Unopened(format!("{e:#}")),
    };
    let id = match chamber.connect().await {
        Ok(id) => id,
        Err(e) => {
            return match e.kind() {
                ChamberErrorKind::Timeout | ChamberErrorKind::Garbled => {
                    Step::Silent(e.to_string())
                }
                ChamberErrorKind::Link => Step::Unopened(e.to_string()),
                _ => Step::Refused(e.to_string()),
            };
        }
    };
    match chamber.read().await {
        Ok(reading) => Step::Read(ChamberFound {
            port,
            named: "",
            model: id.model,
            detail: id.detail,
            reading,
        }),
        Err(e) => Step::Unread(id.model, e.to_string()),
    }
}

/// Who answers on the chamber's port, asked as the meter's and the table's ports are (the
/// chamber's own link closed first).
async fn second_look(spec: &PortSpec, baud: u32) -> Who {
    let options = LinkOptions {
        baud,
        ..LinkOptions::default()
    };
    match gyrocal_link::open_port(spec, &options).await {
        Ok(mut link) => answer::look(&mut link).await,
        Err(e) => Who::Unopened {
            error: e.to_string(),
        },
    }
}

/// What to check on a chamber's link when nothing answered.
fn causes(spec: &PortSpec, baud: u32, slave: u8) -> String {
    match spec {
        PortSpec::Tcp { host, port } => format!(
            "check that {host} is reachable and its Modbus TCP server (or the controller's \
             gateway) listens on port {port}, and that the unit id is {slave}"
        ),
        _ => format!(
            "check that the controller is on, that its communications are set to {baud} baud \
             8N1 and Modbus address {slave} as the plan says, \
             the RS-232/RS-485 cable and converter, and that no other program holds the port"
        ),
    }
}
