//! The Watlow F4 driver's settings: what is confirmed has a default, what is not (alarm
//! registers, a "chamber on" event output) is an explicit option that is off by default.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::ChamberError;

/// The F4's input that holds the product's (the gyro's) temperature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProductInput {
    /// No product sensor: readings have `product_c: None`.
    None,
    /// Input 2 (register 104, decimals in 616): a second sensor on most chambers.
    #[default]
    Input2,
    /// Input 3 (register 108, decimals in 626): the product on cascade models.
    Input3,
}

impl ProductInput {
    /// From the plan's number: 0 (none), 2 or 3.
    pub fn from_number(n: u8) -> Option<ProductInput> {
        match n {
            0 => Some(ProductInput::None),
            2 => Some(ProductInput::Input2),
            3 => Some(ProductInput::Input3),
            _ => None,
        }
    }

    /// The input's number (0 for none).
    pub fn number(self) -> u8 {
        match self {
            ProductInput::None => 0,
            ProductInput::Input2 => 2,
            ProductInput::Input3 => 3,
        }
    }
}

/// An alarm read from a holding register: active when `value & mask == active`.
///
/// Not confirmed for the F4 (chamber.md: Espec's library reads the limit controllers through
/// digital inputs 1061 + 2(N−1) compared with 201 + 12(N−1), for one chamber family), so no
/// alarm is read unless configured: the wiring differs from one chamber builder to the next.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AlarmRegister {
    /// The holding register.
    pub register: u16,
    /// The bits looked at.
    #[serde(default = "all_bits")]
    pub mask: u16,
    /// The masked value that means "alarm".
    pub active: u16,
    /// The alarm's name as the operator is told (`door open`, `over-temperature`).
    pub name: String,
}

fn all_bits() -> u16 {
    0xFFFF
}

/// The Watlow F4 driver's settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WatlowConfig {
    /// The Modbus slave address, 1–247. Default 1 (the F4's factory setting).
    pub slave: u8,
    /// The product's input. Default input 2.
    pub product_input: ProductInput,
    /// The lowest setpoint the driver sends, °C (narrowed at connect by the F4's input 1
    /// range, registers 602/603). Default −40.
    pub min_c: f64,
    /// The highest setpoint the driver sends, °C (narrowed likewise). Default 85.
    pub max_c: f64,
    /// How long a reply may take. Default 1 s.
    #[serde(with = "millis")]
    pub reply_timeout: Duration,
    /// How many times a read is asked again after a lost or garbled reply. Default 2.
    pub retries: u32,
    /// Alarm registers to read with every reading. Default none (not confirmed: see
    /// [`AlarmRegister`]).
    pub alarms: Vec<AlarmRegister>,
    /// The digital event output (1–8, register 2000 + 10·(N−1)) a chamber builder wired to
    /// "chamber on", used for the `standby` and `off` safe states (written 0, read back).
    /// Not confirmed: default none, and then `standby`/`off` are reported not confirmed.
    pub chamber_on_output: Option<u8>,
    /// The controller's reply latency for the timing model (time between the end of a
    /// request and the start of its reply). Default 50 ms: an assumption (the F4's manual
    /// gives no figure here), on the safe side of what Modbus controllers of its class do.
    #[serde(with = "millis")]
    pub reply_latency: Duration,
}

impl Default for WatlowConfig {
    fn default() -> Self {
        WatlowConfig {
            slave: 1,
            product_input: ProductInput::Input2,
            min_c: -40.0,
            max_c: 85.0,
            reply_timeout: Duration::from_secs(1),
            retries: 2,
            alarms: Vec::new(),
            chamber_on_output: None,
            reply_latency: Duration::from_millis(50),
        }
    }
}

/// The baud rates the F4's communications menu offers.
pub const WATLOW_BAUDS: [u32; 3] = [9600, 19200, 38400];

impl WatlowConfig {
    /// Checks the settings before anything is opened (kind Setup, naming the setting).
    pub fn validate(&self, device: &str) -> Result<(), ChamberError> {
        let bad = |what: String| {
            Err(ChamberError::Setup {
                device: device.to_string(),
                what,
            })
        };
        if !(1..=247).contains(&self.slave) {
            return bad(format!("Modbus slave address {} is not 1–247", self.slave));
        }
        if !self.min_c.is_finite() || !self.max_c.is_finite() || self.min_c >= self.max_c {
            return bad(format!(
                "setpoint limits {} .. {} °C are not a range",
                self.min_c, self.max_c
            ));
        }
        if self.reply_timeout.is_zero() || self.reply_timeout > Duration::from_secs(60) {
            return bad(format!(
                "reply timeout {:?} is not within (0, 60 s]",
                self.reply_timeout
            ));
        }
        if self.retries > 10 {
            return bad(format!("{} retries is more than 10", self.retries));
        }
        if let Some(n) = self.chamber_on_output
            && !(1..=8).contains(&n)
        {
            return bad(format!("chamber_on_output {n} is not an event output 1–8"));
        }
        if self.alarms.len() > 16 {
            return bad(format!(
                "{} alarm registers is more than 16",
                self.alarms.len()
            ));
        }
        Ok(())
    }
}

mod millis {
    use serde::{Deserialize, Deserializer, Serializer};
    use std::time::Duration;

    pub fn serialize<S: Serializer>(d: &Duration, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(u64::try_from(d.as_millis()).unwrap_or(u64::MAX))
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        Ok(Duration::from_millis(u64::deserialize(d)?))
    }
}
