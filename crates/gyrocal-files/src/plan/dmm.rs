//! `[dmm]`: the multimeter (its model, port, link, and the DC-volts settings), with its keys,
//! defaults and checks against the instruments' own facts (each from its driver crate, built
//! without I/O).

use serde::{Deserialize, Serialize};

use super::error::PlanError;
use super::raw::{RawInt, S, Spans};
use super::schema::{IntRule, KeySchema, Kind};
use super::validate::Ctx;
use super::{BAUD_RATES, Port};

// The instruments' facts are their crates' (one copy each, built without I/O for this
// synchronous crate); the plan checks against them.
/// Mains frequencies the meter integrates against: the 34401A's.
pub use gyrocal_hp34401a::facts::LINE_HZ;

/// Integration times (power-line cycles) the HP 34401A offers for DC volts: its driver's.
pub use gyrocal_hp34401a::facts::NPLC_VALUES;

/// DC voltage ranges, in volts: the 34401A's (the Truevolts' are the same; a test keeps it so).
pub use gyrocal_hp34401a::facts::RANGES as RANGES_V;

/// Every integration time some supported meter offers: the Truevolt 34465A/70A's list, which
/// holds the 34401A's and the 34460A/61A's (a test keeps it so). The plan refuses anything
/// else at once, with the line and column; which of these the named model offers is the
/// driver crate's fact, checked by the CLI (`gyrocal check`, `gyrocal run`) before anything
/// opens.
pub use gyrocal_truevolt::facts::NPLC_65_70 as KNOWN_NPLC_VALUES;

/// The keys of `[dmm]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("model", Kind::Text, false),
    ("port", Kind::Text, true),
    ("baud", Kind::Int(IntRule::OneOf(&BAUD_RATES)), false),
    ("framing", Kind::Text, false),
    ("range_v", Kind::Number, false),
    ("nplc", Kind::Number, false),
    ("autozero", Kind::Bool, false),
    ("line_hz", Kind::Int(IntRule::OneOf(&LINE_HZ)), false),
    ("acquisition", Kind::Text, false),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDmm {
    pub(super) model: Option<S<String>>,
    pub(super) port: S<String>,
    pub(super) baud: Option<S<RawInt>>,
    pub(super) framing: Option<S<String>>,
    pub(super) range_v: Option<S<f64>>,
    pub(super) nplc: Option<S<f64>>,
    pub(super) autozero: Option<S<bool>>,
    pub(super) line_hz: Option<S<RawInt>>,
    pub(super) acquisition: Option<S<String>>,
}

/// `[dmm]` as parsed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DmmDoc {
    /// `34401a` (the default), `34460a`, `34461a`, `34465a` or `34470a`. Left out of the
    /// serialised form when it is the default, so a 34401A plan's hash is what it was before
    /// the key existed.
    #[serde(default = "default_model", skip_serializing_if = "is_default_model")]
    pub model: String,
    /// Serial device path or `tcp://HOST:PORT`.
    pub port: String,
    /// Serial baud rate.
    pub baud: i64,
    /// `8N2`, `7E2` or `7O2`.
    pub framing: String,
    /// DC range, V.
    pub range_v: f64,
    /// Integration time, power-line cycles.
    pub nplc: f64,
    /// Autozero on or off.
    pub autozero: bool,
    /// Mains frequency, Hz.
    pub line_hz: i64,
    /// `auto`, `stream`, `memory` or `poll`.
    pub acquisition: String,
}

fn default_model() -> String {
    DmmModel::Hp34401a.as_str().into()
}

#[allow(clippy::ptr_arg)] // serde's skip_serializing_if passes a &String
fn is_default_model(m: &String) -> bool {
    m.eq_ignore_ascii_case(DmmModel::Hp34401a.as_str())
}

impl DmmDoc {
    /// `[dmm]` as written, defaults filled in, spans kept.
    pub(super) fn from_raw(m: RawDmm, sp: &mut Spans) -> Result<DmmDoc, (&'static str, String)> {
        Ok(DmmDoc {
            model: sp.opt("dmm.model", m.model, default_model()),
            port: sp.take("dmm.port", m.port),
            baud: sp.int("dmm.baud", m.baud, 9600)?,
            framing: sp.opt("dmm.framing", m.framing, "8N2".into()),
            range_v: sp.opt("dmm.range_v", m.range_v, 10.0),
            nplc: sp.opt("dmm.nplc", m.nplc, 1.0),
            autozero: sp.opt("dmm.autozero", m.autozero, true),
            line_hz: sp.int("dmm.line_hz", m.line_hz, 50)?,
            acquisition: sp.opt("dmm.acquisition", m.acquisition, "auto".into()),
        })
    }
}

/// The multimeter model a plan names (`[dmm] model`). The plan knows the names only; each
/// model's facts (NPLC values, memory) are its driver crate's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum DmmModel {
    /// HP 34401A on RS-232 or GPIB (the default).
    #[default]
    Hp34401a,
    /// Keysight Truevolt 34460A, over LAN.
    K34460a,
    /// Keysight Truevolt 34461A, over LAN.
    K34461a,
    /// Keysight Truevolt 34465A, over LAN.
    K34465a,
    /// Keysight Truevolt 34470A, over LAN.
    K34470a,
}

impl DmmModel {
    /// Every model.
    pub const ALL: [DmmModel; 5] = [
        DmmModel::Hp34401a,
        DmmModel::K34460a,
        DmmModel::K34461a,
        DmmModel::K34465a,
        DmmModel::K34470a,
    ];

    /// The name used in plan files.
    pub fn as_str(self) -> &'static str {
        match self {
            DmmModel::Hp34401a => "34401a",
            DmmModel::K34460a => "34460a",
            DmmModel::K34461a => "34461a",
            DmmModel::K34465a => "34465a",
            DmmModel::K34470a => "34470a",
        }
    }

    /// The model as its maker writes it (`34401A`, `34461A`), for messages.
    pub fn name(self) -> String {
        self.as_str().to_ascii_uppercase()
    }

    /// True for a Keysight Truevolt: which driver family speaks to it. For what the family
    /// implies, ask the property itself: [`DmmModel::lan_only`] for how it is reached,
    /// [`DmmSettings::scpi_socket`] for what its port is, [`DmmModel::nplc_values`] for what it
    /// offers.
    pub fn is_truevolt(self) -> bool {
        self != DmmModel::Hp34401a
    }

    /// True for a meter reached over LAN only (the Truevolts): its port must be
    /// `tcp://HOST:5025`, its own SCPI socket.
    pub fn lan_only(self) -> bool {
        self.truevolt().is_some()
    }

    /// The integration times (power-line cycles) this model offers for DC volts: its driver
    /// crate's fact (the 34460A/61A lack the 34465A/70A's 0.06).
    pub fn nplc_values(self) -> &'static [f64] {
        match self.truevolt() {
            None => &NPLC_VALUES,
            Some(m) => m.nplc_values(),
        }
    }

    /// The Truevolt crate's model, for a Truevolt.
    fn truevolt(self) -> Option<gyrocal_truevolt::facts::Model> {
        use gyrocal_truevolt::facts::Model;
        match self {
            DmmModel::Hp34401a => None,
            DmmModel::K34460a => Some(Model::M34460A),
            DmmModel::K34461a => Some(Model::M34461A),
            DmmModel::K34465a => Some(Model::M34465A),
            DmmModel::K34470a => Some(Model::M34470A),
        }
    }
}

/// RS-232 character framing (`8N2`, `7E2`, `7O2`): the link's type, named in plans as it
/// displays.
pub use gyrocal_link::Framing;

/// How the multimeter acquires a step's readings (see `hp34401a.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Acquisition {
    /// Let the sequencer choose: stream when the wire keeps up, memory otherwise.
    Auto,
    /// `READ?` with a sample count: readings stream as they are taken.
    Stream,
    /// `INIT;*OPC?` then `FETC?` in bursts of at most 512 readings.
    Memory,
    /// One `READ?` per reading (the slow baseline).
    Poll,
}

impl Acquisition {
    /// The name used in plan files.
    pub fn as_str(self) -> &'static str {
        match self {
            Acquisition::Auto => "auto",
            Acquisition::Stream => "stream",
            Acquisition::Memory => "memory",
            Acquisition::Poll => "poll",
        }
    }
}

/// The validated `[dmm]` section.
#[derive(Debug, Clone, PartialEq)]
pub struct DmmSettings {
    /// The meter's model.
    pub model: DmmModel,
    /// Where the multimeter is connected.
    pub port: Port,
    /// Serial baud rate (one of [`BAUD_RATES`]).
    pub baud: u32,
    /// Character framing.
    pub framing: Framing,
    /// DC range, V (one of [`RANGES_V`]).
    pub range_v: f64,
    /// Integration time in power-line cycles (one of [`KNOWN_NPLC_VALUES`]; the model's own
    /// list is checked by its driver crate).
    pub nplc: f64,
    /// Autozero on (doubles each reading's time).
    pub autozero: bool,
    /// Mains frequency, 50 or 60 Hz.
    pub line_hz: u32,
    /// Acquisition strategy.
    pub acquisition: Acquisition,
}

impl DmmSettings {
    /// As the document writes it.
    pub(super) fn to_doc(&self) -> DmmDoc {
        DmmDoc {
            model: self.model.as_str().into(),
            port: self.port.to_string(),
            baud: self.baud.into(),
            framing: self.framing.to_string(),
            range_v: self.range_v,
            nplc: self.nplc,
            autozero: self.autozero,
            line_hz: self.line_hz.into(),
            acquisition: self.acquisition.as_str().into(),
        }
    }

    /// True when the meter's port is its own SCPI socket (a LAN meter's `tcp://HOST:5025`:
    /// device clear reconnects), not a serial-to-Ethernet converter in front of an RS-232
    /// meter.
    pub fn scpi_socket(&self) -> bool {
        self.model.lan_only() && self.port.is_tcp()
    }
}

/// Checks `[dmm]`; its port must differ from the table's (`table_port`).
pub(super) fn validate(
    m: DmmDoc,
    table_port: &Port,
    cx: &Ctx<'_>,
) -> Result<DmmSettings, PlanError> {
    let model = DmmModel::ALL
        .into_iter()
        .find(|d| d.as_str().eq_ignore_ascii_case(m.model.trim()))
        .ok_or_else(|| {
            cx.err(
                "dmm.model",
                format!(
                    "must be \"34401a\", \"34460a\", \"34461a\", \"34465a\" or \"34470a\" (got {:?})",
                    m.model
                ),
            )
        })?;
    let dmm_port = cx.port("dmm.port", &m.port)?;
    if model.lan_only() && !dmm_port.is_tcp() {
        return Err(cx.err(
            "dmm.port",
            format!(
                "a {} is reached over LAN: use tcp://HOST:5025 (got {dmm_port})",
                model.as_str()
            ),
        ));
    }
    if &dmm_port == table_port {
        return Err(cx.err(
            "dmm.port",
            format!("is the same as [table] port ({dmm_port})"),
        ));
    }
    let dmm_baud = cx.one_of_u32("dmm.baud", m.baud, &BAUD_RATES)?;
    let Ok(framing) = m.framing.parse::<Framing>() else {
        return Err(cx.err(
            "dmm.framing",
            format!("must be \"8N2\", \"7E2\" or \"7O2\" (got {:?})", m.framing),
        ));
    };
    let range_v = cx.one_of_f64("dmm.range_v", m.range_v, &RANGES_V)?;
    let nplc = cx.one_of_f64("dmm.nplc", m.nplc, &KNOWN_NPLC_VALUES)?;
    let line_hz = cx.one_of_u32("dmm.line_hz", m.line_hz, &LINE_HZ)?;
    let acquisition = match m.acquisition.to_ascii_lowercase().as_str() {
        "auto" => Acquisition::Auto,
        "stream" => Acquisition::Stream,
        "memory" => Acquisition::Memory,
        "poll" => Acquisition::Poll,
        _ => {
            return Err(cx.err(
                "dmm.acquisition",
                format!(
                    "must be auto, stream, memory or poll (got {:?})",
                    m.acquisition
                ),
            ));
        }
    };
    // what the named model offers: its driver crate's facts (this was `gyrocal check`'s and
    // `gyrocal run`'s own check; it is the plan's, so a library user never holds a plan the
    // CLI refuses)
    if model.lan_only() && acquisition == Acquisition::Poll {
        return Err(cx.err(
            "dmm.acquisition",
            format!(
                "= \"poll\" is a 34401A baseline; the {} streams (use auto, stream or memory)",
                model.name()
            ),
        ));
    }
    if !model.nplc_values().contains(&nplc) {
        let offered: Vec<String> = model.nplc_values().iter().map(f64::to_string).collect();
        return Err(cx.err(
            "dmm.nplc",
            format!(
                "= {nplc} is not offered by the {}: use one of {}",
                model.name(),
                offered.join(", ")
            ),
        ));
    }
    Ok(DmmSettings {
        model,
        port: dmm_port,
        baud: dmm_baud,
        framing,
        range_v,
        nplc,
        autozero: m.autozero,
        line_hz,
        acquisition,
    })
}
