//! The Truevolt models' facts, written once (`shared/docs/instruments.md`); the plan, the CLI,
//! the driver and the simulator take them from here.
//!
//! \[U\] marks a fact not confirmed from a primary document: it is a documented, configurable
//! default ([`crate::TimingDefaults`]), never a constant buried in code.

use std::fmt;
use std::str::FromStr;

use gyrocal_meter::DcVolts;
use serde::{Deserialize, Serialize};

/// DC voltage ranges of every Truevolt model, volts.
pub const RANGES_V: [f64; 5] = [0.1, 1.0, 10.0, 100.0, 1000.0];
/// Integration times (power-line cycles) of the 34460A and 34461A.
pub const NPLC_60_61: [f64; 5] = [0.02, 0.2, 1.0, 10.0, 100.0];
/// Integration times of the 34465A and 34470A without the DIG option (0.06 added; the DIG
/// option's 0.001/0.002/0.006 are not offered here).
pub const NPLC_65_70: [f64; 6] = [0.02, 0.06, 0.2, 1.0, 10.0, 100.0];
/// Readings the memory holds with the MEM option (34465A and 34470A only).
pub const MEM_OPTION_READINGS: usize = 2_000_000;
/// The SCPI socket port of Keysight instruments [U: Keysight's standard; the Truevolt guide
/// itself was not checked].
pub const SCPI_SOCKET_PORT: u16 = 5025;
/// Most readings one `INIT` takes (`SAMP:COUN` maximum) [U: 1,000,000 assumed for every
/// model; a longer step is taken as several acquisitions].
pub const MAX_SAMPLE_COUNT: usize = 1_000_000;

/// A Truevolt model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Model {
    /// 34460A: 1,000 readings of memory.
    #[serde(rename = "34460a", alias = "34460A")]
    M34460A,
    /// 34461A: 10,000 readings.
    #[serde(rename = "34461a", alias = "34461A")]
    M34461A,
    /// 34465A: 50,000 readings (2,000,000 with MEM).
    #[serde(rename = "34465a", alias = "34465A")]
    M34465A,
    /// 34470A: 50,000 readings (2,000,000 with MEM).
    #[serde(rename = "34470a", alias = "34470A")]
    M34470A,
}

impl Model {
    /// Every model.
    pub const ALL: [Model; 4] = [
        Model::M34460A,
        Model::M34461A,
        Model::M34465A,
        Model::M34470A,
    ];

    /// The model number as `*IDN?` writes it (`34461A`).
    pub fn name(self) -> &'static str {
        match self {
            Model::M34460A => "34460A",
            Model::M34461A => "34461A",
            Model::M34465A => "34465A",
            Model::M34470A => "34470A",
        }
    }

    /// The name plan files use (`34461a`).
    pub fn key(self) -> &'static str {
        match self {
            Model::M34460A => "34460a",
            Model::M34461A => "34461a",
            Model::M34465A => "34465a",
            Model::M34470A => "34470a",
        }
    }

    /// The model an `*IDN?` model field names, if it is a Truevolt.
    pub fn from_idn(field: &str) -> Option<Model> {
        Model::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(field.trim()))
    }

    /// Readings the memory holds; `mem_option` (the MEM option, 34465A/70A only) makes it
    /// 2,000,000.
    pub fn memory(self, mem_option: bool) -> usize {
        match self {
            Model::M34460A => 1_000,
            Model::M34461A => 10_000,
            Model::M34465A | Model::M34470A if mem_option => MEM_OPTION_READINGS,
            Model::M34465A | Model::M34470A => 50_000,
        }
    }

    /// Whether the MEM option exists for this model.
    pub fn has_mem_option(self) -> bool {
        matches!(self, Model::M34465A | Model::M34470A)
    }

    /// The NPLC values the model offers.
    pub fn nplc_values(self) -> &'static [f64] {
        match self {
            Model::M34460A | Model::M34461A => &NPLC_60_61,
            Model::M34465A | Model::M34470A => &NPLC_65_70,
        }
    }

    /// The `*IDN?` models a Truevolt of this model may pose as (`SYST:IDEN`): the 34401A for
    /// every model, the 34410A/34411A for the 34465A/70A.
    pub fn personalities(self) -> &'static [&'static str] {
        match self {
            Model::M34460A | Model::M34461A => &["34401A"],
            Model::M34465A | Model::M34470A => &["34401A", "34410A", "34411A"],
        }
    }
}

impl fmt::Display for Model {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Model {
    type Err = String;
    fn from_str(s: &str) -> Result<Model, String> {
        Model::ALL
            .into_iter()
            .find(|m| m.key().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                format!("{s:?} is not a Truevolt model (34460a, 34461a, 34465a or 34470a)")
            })
    }
}

/// A setting a model does not offer: which key, and a message naming the model and the
/// allowed values.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct FactsError {
    /// The plan key (`nplc`, `range_v`, `line_hz`, `mem_option`).
    pub key: &'static str,
    /// What is wrong.
    pub message: String,
}

fn list(values: &[f64]) -> String {
    values
        .iter()
        .map(f64::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Checks DC-volts settings against `model` (synchronous: the CLI calls it before anything
/// opens). The error names the model and the values it allows.
pub fn check(model: Model, settings: &DcVolts, mem_option: bool) -> Result<(), FactsError> {
    if !model.nplc_values().contains(&settings.nplc) {
        return Err(FactsError {
            key: "nplc",
            message: format!(
                "NPLC {} is not offered by the {model}: use one of {}",
                settings.nplc,
                list(model.nplc_values())
            ),
        });
    }
    if let Some(r) = settings.range_v
        && !RANGES_V.contains(&r)
    {
        return Err(FactsError {
            key: "range_v",
            message: format!(
                "range {r} V is not offered by the {model}: use one of {}",
                list(&RANGES_V)
            ),
        });
    }
    if settings.line_hz != 50 && settings.line_hz != 60 {
        return Err(FactsError {
            key: "line_hz",
            message: format!(
                "line frequency {} Hz is neither 50 nor 60",
                settings.line_hz
            ),
        });
    }
    if mem_option && !model.has_mem_option() {
        return Err(FactsError {
            key: "mem_option",
            message: format!("the {model} has no MEM option (34465A and 34470A only)"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dcv(nplc: f64) -> DcVolts {
        DcVolts {
            range_v: Some(10.0),
            nplc,
            autozero: true,
            line_hz: 50,
        }
    }

    #[test]
    fn memory_and_nplc_per_model() {
        assert_eq!(Model::M34460A.memory(false), 1_000);
        assert_eq!(Model::M34461A.memory(true), 10_000);
        assert_eq!(Model::M34465A.memory(false), 50_000);
        assert_eq!(Model::M34470A.memory(true), 2_000_000);
        assert!(check(Model::M34465A, &dcv(0.06), false).is_ok());
        let e = check(Model::M34461A, &dcv(0.06), false).unwrap_err();
        assert_eq!(e.key, "nplc");
        assert!(e.message.contains("34461A"), "{e}");
        assert!(e.message.contains("0.02, 0.2, 1, 10, 100"), "{e}");
        assert!(check(Model::M34460A, &dcv(1.0), true).is_err());
        assert_eq!("34465A".parse::<Model>(), Ok(Model::M34465A));
        assert_eq!(Model::from_idn("34470A"), Some(Model::M34470A));
        assert!("34401a".parse::<Model>().is_err());
    }
}
