//! `[chamber]`: the thermal chamber a temperature series drives (the bench's third role, after
//! the meter and the table). Its keys, defaults and rules live here; the driver itself is the
//! `gyrocal-chamber` crate, which this synchronous crate does not depend on (it needs an
//! async runtime), so the CLI maps these settings onto the driver's configuration.
//!
//! Why the limits are the plan's and not only the controller's: a gyro's operating range is
//! usually narrower than the chamber's, and a setpoint outside it is refused at `gyrocal
//! check`, before anything is opened, with the line of the temperature that breaks it.

use serde::{Deserialize, Serialize};

use super::Port;
use super::error::PlanError;
use super::raw::{RawInt, S, Spans};
use super::schema::{IntRule, KeySchema, Kind};
use super::validate::Ctx;

/// The keys of `[chamber]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("model", Kind::Text, true),
    ("port", Kind::Text, true),
    ("baud", Kind::Int(IntRule::OneOf(&CHAMBER_BAUDS)), false),
    ("slave", Kind::Int(IntRule::Range(1, 247)), false),
    ("ramp_c_per_min", Kind::Number, false),
    ("min_c", Kind::Number, false),
    ("max_c", Kind::Number, false),
    ("safe_state", Kind::Text, false),
    ("ambient_c", Kind::Number, false),
    ("product_input", Kind::Int(IntRule::OneOf(&[2, 3])), false),
    ("alarm_registers", Kind::Tables, false),
    ("chamber_on_output", Kind::Int(IntRule::Range(1, 8)), false),
];

/// The baud rates `[chamber] baud` takes: the Watlow F4 offers 9600, 19200 and 38400 (the
/// driver's `WATLOW_BAUDS`); an Espec controller's are set on its panel, 9600 or 19200 on
/// the SH-641 and SU series.
pub const CHAMBER_BAUDS: [u32; 3] = [9600, 19200, 38400];
/// The baud rates of an Espec controller's serial port.
pub const ESPEC_BAUDS: [u32; 2] = [9600, 19200];

/// Default `[chamber] baud`.
pub const DEFAULT_CHAMBER_BAUD: u32 = 9600;
/// Default `[chamber] ramp_c_per_min`, °C/min: slow enough that a gyro's case and inside do
/// not lag far behind the air (IEEE 1431 asks for ≤ 1 °C/min in most sequences).
pub const DEFAULT_RAMP_C_PER_MIN: f64 = 1.0;
/// Default `[chamber] min_c`, °C.
pub const DEFAULT_MIN_C: f64 = -40.0;
/// Default `[chamber] max_c`, °C.
pub const DEFAULT_MAX_C: f64 = 85.0;
/// Default `[chamber] ambient_c`, °C (the ambient safe state's setpoint).
pub const DEFAULT_AMBIENT_C: f64 = 23.0;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawChamber {
    model: S<String>,
    port: S<String>,
    baud: Option<S<RawInt>>,
    slave: Option<S<RawInt>>,
    ramp_c_per_min: Option<S<f64>>,
    min_c: Option<S<f64>>,
    max_c: Option<S<f64>>,
    safe_state: Option<S<String>>,
    ambient_c: Option<S<f64>>,
    product_input: Option<S<RawInt>>,
    alarm_registers: Option<Vec<RawAlarm>>,
    chamber_on_output: Option<S<RawInt>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawAlarm {
    register: S<i64>,
    name: S<String>,
    mask: Option<S<i64>>,
    active: Option<S<i64>>,
}

/// One alarm register of a Watlow F4 as the plan names it (`{ register = 1061, name = "door
/// open" }`): the run stops when `value & mask == active`. `mask` defaults to every bit,
/// `active` to 1 (the F4's alarm status registers read 1 while the alarm is latched).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlarmRegisterDoc {
    /// The holding register.
    pub register: i64,
    /// The alarm's name as the operator is told.
    pub name: String,
    /// The bits looked at.
    pub mask: i64,
    /// The masked value that means "alarm".
    pub active: i64,
}

/// `[chamber]` as parsed (defaults filled in).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChamberDoc {
    /// `watlow_f4` or `espec`.
    pub model: String,
    /// Serial device or `tcp://HOST:PORT` (not part of the plan's hash).
    pub port: String,
    /// Serial baud rate.
    pub baud: i64,
    /// Modbus slave address.
    pub slave: i64,
    /// The run steps the setpoint towards each target at this rate, °C/min.
    pub ramp_c_per_min: f64,
    /// Lowest setpoint allowed, °C.
    pub min_c: f64,
    /// Highest setpoint allowed, °C.
    pub max_c: f64,
    /// `ambient`, `standby` or `off`.
    pub safe_state: String,
    /// The ambient safe state's setpoint, °C.
    pub ambient_c: f64,
    /// The Watlow input carrying the gyro's temperature (2 or 3).
    pub product_input: i64,
    /// Alarm registers read with every reading (Watlow).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub alarm_registers: Vec<AlarmRegisterDoc>,
    /// The digital output wired to "chamber on" (Watlow standby/off).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber_on_output: Option<i64>,
}

impl ChamberDoc {
    /// `[chamber]` as written, defaults filled in, spans kept. A whole-number key that is not
    /// a 64-bit integer is an error `(key, message)`.
    pub(super) fn from_raw(
        c: RawChamber,
        sp: &mut Spans,
    ) -> Result<ChamberDoc, (&'static str, String)> {
        let mut alarm_registers = Vec::new();
        for (i, a) in c.alarm_registers.into_iter().flatten().enumerate() {
            let key = |k: &str| format!("chamber.alarm_registers[{i}].{k}");
            alarm_registers.push(AlarmRegisterDoc {
                register: sp.take(&key("register"), a.register),
                name: sp.take(&key("name"), a.name),
                mask: a.mask.map_or(0xFFFF, |v| sp.take(&key("mask"), v)),
                active: a.active.map_or(1, |v| sp.take(&key("active"), v)),
            });
        }
        let chamber_on_output = match c.chamber_on_output {
            None => None,
            Some(v) => Some(sp.int("chamber.chamber_on_output", Some(v), 0)?),
        };
        Ok(ChamberDoc {
            model: sp.take("chamber.model", c.model),
            port: sp.take("chamber.port", c.port),
            baud: sp.int("chamber.baud", c.baud, i64::from(DEFAULT_CHAMBER_BAUD))?,
            slave: sp.int("chamber.slave", c.slave, 1)?,
            ramp_c_per_min: sp.opt(
                "chamber.ramp_c_per_min",
                c.ramp_c_per_min,
                DEFAULT_RAMP_C_PER_MIN,
            ),
            min_c: sp.opt("chamber.min_c", c.min_c, DEFAULT_MIN_C),
            max_c: sp.opt("chamber.max_c", c.max_c, DEFAULT_MAX_C),
            safe_state: sp.opt(
                "chamber.safe_state",
                c.safe_state,
                SafeStateChoice::Ambient.as_str().into(),
            ),
            ambient_c: sp.opt("chamber.ambient_c", c.ambient_c, DEFAULT_AMBIENT_C),
            product_input: sp.int("chamber.product_input", c.product_input, 2)?,
            alarm_registers,
            chamber_on_output,
        })
    }
}

/// The chamber's controller (`[chamber] model`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChamberModel {
    /// Watlow F4 over Modbus RTU (a serial port) or Modbus TCP (`tcp://HOST:PORT`).
    WatlowF4,
    /// Espec SH-641 / SU text protocol over a serial port (experimental).
    Espec,
}

impl ChamberModel {
    /// All models.
    pub const ALL: [ChamberModel; 2] = [ChamberModel::WatlowF4, ChamberModel::Espec];

    /// As written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            ChamberModel::WatlowF4 => "watlow_f4",
            ChamberModel::Espec => "espec",
        }
    }
}

/// The state the chamber is left in on every way out of a run (`[chamber] safe_state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SafeStateChoice {
    /// Setpoint to `ambient_c`, in control (the default: a gyro brought back to room
    /// temperature under control does not condense water).
    Ambient,
    /// The controller in standby.
    Standby,
    /// The controller off.
    Off,
}

impl SafeStateChoice {
    /// All choices.
    pub const ALL: [SafeStateChoice; 3] = [
        SafeStateChoice::Ambient,
        SafeStateChoice::Standby,
        SafeStateChoice::Off,
    ];

    /// As written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            SafeStateChoice::Ambient => "ambient",
            SafeStateChoice::Standby => "standby",
            SafeStateChoice::Off => "off",
        }
    }
}

/// One validated alarm register.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlarmRegisterSetting {
    /// The holding register.
    pub register: u16,
    /// The alarm's name as the operator is told.
    pub name: String,
    /// The bits looked at.
    pub mask: u16,
    /// The masked value that means "alarm".
    pub active: u16,
}

/// The validated `[chamber]` section (public fields named like the keys).
#[derive(Debug, Clone, PartialEq)]
pub struct ChamberSettings {
    /// The controller.
    pub model: ChamberModel,
    /// Where it is connected.
    pub port: Port,
    /// Serial baud rate.
    pub baud: u32,
    /// Modbus slave address, 1–247.
    pub slave: u8,
    /// The run's ramp of the setpoint, °C/min (> 0).
    pub ramp_c_per_min: f64,
    /// Lowest setpoint allowed, °C.
    pub min_c: f64,
    /// Highest setpoint allowed, °C.
    pub max_c: f64,
    /// The state left on every way out.
    pub safe_state: SafeStateChoice,
    /// The ambient safe state's setpoint, °C (within `[min_c, max_c]`).
    pub ambient_c: f64,
    /// The Watlow input carrying the gyro's temperature, 2 or 3.
    pub product_input: u8,
    /// Alarm registers read with every reading.
    pub alarm_registers: Vec<AlarmRegisterSetting>,
    /// The digital output wired to "chamber on", 1–8.
    pub chamber_on_output: Option<u8>,
}

impl ChamberSettings {
    /// As the document writes it.
    pub(super) fn to_doc(&self) -> ChamberDoc {
        ChamberDoc {
            model: self.model.as_str().into(),
            port: self.port.to_string(),
            baud: i64::from(self.baud),
            slave: i64::from(self.slave),
            ramp_c_per_min: self.ramp_c_per_min,
            min_c: self.min_c,
            max_c: self.max_c,
            safe_state: self.safe_state.as_str().into(),
            ambient_c: self.ambient_c,
            product_input: i64::from(self.product_input),
            alarm_registers: self
                .alarm_registers
                .iter()
                .map(|a| AlarmRegisterDoc {
                    register: i64::from(a.register),
                    name: a.name.clone(),
                    mask: i64::from(a.mask),
                    active: i64::from(a.active),
                })
                .collect(),
            chamber_on_output: self.chamber_on_output.map(i64::from),
        }
    }

    /// The safe state in words, as the run's ending says it (`setpoint 23 °C (ambient)`).
    pub fn describe_safe_state(&self) -> String {
        match self.safe_state {
            SafeStateChoice::Ambient => {
                format!("setpoint {} °C (ambient), in control", self.ambient_c)
            }
            SafeStateChoice::Standby => "standby".into(),
            SafeStateChoice::Off => "off".into(),
        }
    }
}

fn register_u16(cx: &Ctx<'_>, key: &str, v: i64) -> Result<u16, PlanError> {
    u16::try_from(v).map_err(|_| {
        cx.err(
            key,
            format!("= {v} is out of range: write a whole number from 0 to 65535"),
        )
    })
}

/// Validates `[chamber]`: the model, the port, the limits (min < max, within what a chamber
/// can do), the ramp, the safe state and its ambient setpoint, the alarm registers.
pub(super) fn validate(c: &ChamberDoc, cx: &Ctx<'_>) -> Result<ChamberSettings, PlanError> {
    let model = ChamberModel::ALL
        .into_iter()
        .find(|m| m.as_str() == c.model.trim())
        .ok_or_else(|| {
            cx.err(
                "chamber.model",
                format!(
                    "= {:?} is not a chamber this gyrocal drives: write \"watlow_f4\" (Modbus RTU or TCP) or \"espec\" (Espec text protocol)",
                    c.model
                ),
            )
        })?;
    let port = cx.port("chamber.port", &c.port)?;
    if port.is_gpib() {
        return Err(cx.err(
            "chamber.port",
            format!(
                "= {:?} is a GPIB port: a chamber is on a serial port or tcp://HOST:PORT",
                c.port
            ),
        ));
    }
    if model == ChamberModel::Espec && c.port.trim().starts_with("tcp://") {
        return Err(cx.err(
            "chamber.port",
            "an Espec chamber is driven over a serial port: tcp:// is for the Watlow F4's Modbus TCP"
                .into(),
        ));
    }
    let baud = cx.one_of_u32("chamber.baud", c.baud, &CHAMBER_BAUDS)?;
    if model == ChamberModel::Espec && !ESPEC_BAUDS.contains(&baud) {
        return Err(cx.err(
            "chamber.baud",
            format!("= {baud} is not a baud rate of an Espec controller: write 9600 or 19200"),
        ));
    }
    let slave = cx.int_in("chamber.slave", c.slave, 1, 247)?;
    let ramp = cx.finite("chamber.ramp_c_per_min", c.ramp_c_per_min)?;
    if ramp <= 0.0 || ramp > 100.0 {
        return Err(cx.err(
            "chamber.ramp_c_per_min",
            format!("must be > 0 and <= 100 °C/min (got {ramp})"),
        ));
    }
    let min_c = cx.finite("chamber.min_c", c.min_c)?;
    let max_c = cx.finite("chamber.max_c", c.max_c)?;
    // −273.15 °C is absolute zero; no chamber of a gyro lab goes past these
    for (key, v) in [("chamber.min_c", min_c), ("chamber.max_c", max_c)] {
        if !(-100.0..=250.0).contains(&v) {
            return Err(cx.err(key, format!("must be from -100 to 250 °C (got {v})")));
        }
    }
    if min_c >= max_c {
        return Err(cx.err(
            "chamber.max_c",
            format!("= {max_c} must be above min_c = {min_c}"),
        ));
    }
    let safe_state = SafeStateChoice::ALL
        .into_iter()
        .find(|s| s.as_str() == c.safe_state.trim())
        .ok_or_else(|| {
            cx.err(
                "chamber.safe_state",
                format!(
                    "= {:?} is not a safe state: write \"ambient\" (setpoint to ambient_c, in control), \"standby\" or \"off\"",
                    c.safe_state
                ),
            )
        })?;
    let ambient_c = cx.finite("chamber.ambient_c", c.ambient_c)?;
    if !(min_c..=max_c).contains(&ambient_c) {
        return Err(cx.err(
            "chamber.ambient_c",
            format!("= {ambient_c} °C is outside the chamber's limits [{min_c}, {max_c}] °C"),
        ));
    }
    let product_input = cx.one_of_u32("chamber.product_input", c.product_input, &[2, 3])?;
    let mut alarm_registers = Vec::new();
    for (i, a) in c.alarm_registers.iter().enumerate() {
        let key = |k: &str| format!("chamber.alarm_registers[{i}].{k}");
        let name = a.name.trim();
        if name.is_empty() {
            return Err(cx.err(
                &key("name"),
                "is empty: name the alarm as the operator should read it (\"door open\")".into(),
            ));
        }
        if model == ChamberModel::Espec {
            return Err(cx.err(
                &key("register"),
                "alarm registers are the Watlow F4's: an Espec chamber reports its alarms itself"
                    .into(),
            ));
        }
        alarm_registers.push(AlarmRegisterSetting {
            register: register_u16(cx, &key("register"), a.register)?,
            name: name.to_string(),
            mask: register_u16(cx, &key("mask"), a.mask)?,
            active: register_u16(cx, &key("active"), a.active)?,
        });
    }
    let chamber_on_output = c
        .chamber_on_output
        .map(|v| cx.int_in("chamber.chamber_on_output", v, 1, 8))
        .transpose()?;
    Ok(ChamberSettings {
        model,
        port,
        baud,
        // validated 1..=247 above
        slave: u8::try_from(slave).unwrap_or(1),
        ramp_c_per_min: ramp,
        min_c,
        max_c,
        safe_state,
        ambient_c,
        product_input: u8::try_from(product_input).unwrap_or(2),
        alarm_registers,
        chamber_on_output: chamber_on_output.map(|o| u8::try_from(o).unwrap_or(1)),
    })
}
