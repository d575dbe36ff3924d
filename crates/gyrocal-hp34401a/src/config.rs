//! [`DcvConfig`]: the DC voltage measurement settings, validated before anything is sent.

use serde::{Deserialize, Serialize};

use crate::Error;

use crate::facts::{LINE_HZ, NPLC_VALUES, RANGES};

/// Autozero mode (`ZERO:AUTO`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AutoZero {
    /// A zero measurement after every reading: twice the measurement time, no offset drift.
    #[default]
    On,
    /// No zero measurement.
    Off,
    /// One zero measurement now, then off.
    Once,
}

impl AutoZero {
    /// The SCPI parameter.
    pub fn scpi(self) -> &'static str {
        match self {
            AutoZero::On => "ON",
            AutoZero::Off => "OFF",
            AutoZero::Once => "ONCE",
        }
    }
}

/// Trigger source (`TRIG:SOUR`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TriggerSource {
    /// Trigger at once (the only source [`crate::Hp34401a::acquire`] supports).
    #[default]
    Immediate,
    /// Software trigger (`*TRG`).
    Bus,
    /// Rear-panel external trigger input.
    External,
}

impl TriggerSource {
    /// The SCPI parameter.
    pub fn scpi(self) -> &'static str {
        match self {
            TriggerSource::Immediate => "IMM",
            TriggerSource::Bus => "BUS",
            TriggerSource::External => "EXT",
        }
    }
}

/// DC voltage measurement settings.
///
/// Deserialises from TOML or JSON with every field optional:
///
/// ```toml
/// range = 10.0      # volts; leave out for autorange
/// nplc = 1.0
/// autozero = "on"
/// line_hz = 50
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DcvConfig {
    /// Fixed range in volts (0.1, 1, 10, 100 or 1000); `None` (the default) is autorange.
    pub range: Option<f64>,
    /// Integration time in power-line cycles: 0.02, 0.2, 1, 10 or 100. Default 10 (the meter's
    /// power-on value, 6½ digits).
    pub nplc: f64,
    /// Autozero. Default on.
    pub autozero: AutoZero,
    /// Input impedance automatic (>10 GΩ on the 0.1, 1 and 10 V ranges) when true; a fixed
    /// 10 MΩ when false (the default, as after `*RST`).
    pub input_impedance_auto: bool,
    /// Trigger source. Default immediate.
    pub trigger_source: TriggerSource,
    /// Trigger delay in seconds before every sample; `None` (the default) is the automatic delay.
    pub trigger_delay: Option<f64>,
    /// Power-line frequency in hertz, 50 or 60: sets the integration time. Default 50.
    pub line_hz: u32,
    /// Baud rate of the link, used only for the timing estimates. Default 9600.
    pub baud: u32,
    /// The meter is reached over GPIB (through a controller): its wire time is the bus's,
    /// [`crate::timing::GPIB_CHAR_TIME`] per character, and `baud` is not used. Default
    /// false (RS-232).
    #[serde(default)]
    pub gpib: bool,
}

impl Default for DcvConfig {
    fn default() -> Self {
        DcvConfig {
            range: None,
            nplc: 10.0,
            autozero: AutoZero::On,
            input_impedance_auto: false,
            trigger_source: TriggerSource::Immediate,
            trigger_delay: None,
            line_hz: 50,
            baud: 9600,
            gpib: false,
        }
    }
}

impl DcvConfig {
    /// Checks every setting against what the meter accepts.
    pub fn validate(&self) -> Result<(), Error> {
        let bad = |m: String| Err(Error::Config(m));
        if !NPLC_VALUES.contains(&self.nplc) {
            return bad(format!(
                "NPLC {} is not one of 0.02, 0.2, 1, 10, 100",
                self.nplc
            ));
        }
        if let Some(r) = self.range
            && !RANGES.contains(&r)
        {
            return bad(format!("range {r} V is not one of 0.1, 1, 10, 100, 1000"));
        }
        if let Some(d) = self.trigger_delay
            && !(d.is_finite() && (0.0..=3600.0).contains(&d))
        {
            return bad(format!("trigger delay {d} s is outside 0..3600 s"));
        }
        if !LINE_HZ.contains(&self.line_hz) {
            return bad(format!(
                "line frequency {} Hz is neither 50 nor 60",
                self.line_hz
            ));
        }
        if !self.gpib && !gyrocal_link::SUPPORTED_BAUDS.contains(&self.baud) {
            return bad(format!(
                "baud {} is not one of {:?}",
                self.baud,
                gyrocal_link::SUPPORTED_BAUDS
            ));
        }
        Ok(())
    }

    /// The command lines that apply this configuration, in order (each well under 100 characters).
    pub fn commands(&self) -> Vec<String> {
        let mut c = Vec::new();
        match self.range {
            Some(r) => {
                c.push(format!("CONF:VOLT:DC {}", fmt_num(r)));
            }
            None => {
                c.push("CONF:VOLT:DC DEF".to_string());
                c.push("VOLT:DC:RANG:AUTO ON".to_string());
            }
        }
        c.push(format!("VOLT:DC:NPLC {}", fmt_num(self.nplc)));
        c.push(format!("ZERO:AUTO {}", self.autozero.scpi()));
        c.push(format!(
            "INP:IMP:AUTO {}",
            if self.input_impedance_auto {
                "ON"
            } else {
                "OFF"
            }
        ));
        c.push(format!("TRIG:SOUR {}", self.trigger_source.scpi()));
        match self.trigger_delay {
            Some(d) => c.push(format!("TRIG:DEL {}", fmt_num(d))),
            None => c.push("TRIG:DEL:AUTO ON".to_string()),
        }
        c.push("TRIG:COUN 1".to_string());
        c
    }
}

/// Formats a number the short way (`0.02`, `10`, `1000`).
pub(crate) fn fmt_num(v: f64) -> String {
    format!("{v}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_rejected() {
        assert!(DcvConfig::default().validate().is_ok());
        for nplc in [0.5, 2.0, 0.0, f64::NAN] {
            let c = DcvConfig {
                nplc,
                ..DcvConfig::default()
            };
            assert!(matches!(c.validate(), Err(Error::Config(_))), "{nplc}");
        }
        let c = DcvConfig {
            range: Some(5.0),
            ..DcvConfig::default()
        };
        assert!(c.validate().is_err());
        let c = DcvConfig {
            line_hz: 400,
            ..DcvConfig::default()
        };
        assert!(c.validate().is_err());
        let c = DcvConfig {
            baud: 19200,
            ..DcvConfig::default()
        };
        assert!(c.validate().is_err());
    }

    #[test]
    fn parses_from_toml() {
        let c: DcvConfig =
            toml::from_str("range = 10.0\nnplc = 1.0\nautozero = \"off\"\nline_hz = 60").unwrap();
        assert_eq!(c.range, Some(10.0));
        assert_eq!(c.autozero, AutoZero::Off);
        assert!(toml::from_str::<DcvConfig>("nplcc = 1.0").is_err());
    }
}
