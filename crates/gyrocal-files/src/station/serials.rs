//! The station's serials against the instruments' own: what `gyrocal run` and
//! `gyrocal check --probe` compare once the instruments have identified themselves.
//!
//! A certificate names each instrument by the station file's record (its asset id, serial and
//! calibration). When the instrument that answered reports another serial, the record is not
//! the instrument's and the traceability the certificate claims is in doubt: a warning at
//! the terminal, and a recorded deviation (kind [`SERIAL_MISMATCH`]) that the certificate's
//! deviations section shows. A serial is compared only when both sides have one: an
//! instrument without a record in the station file, or one that reports no serial (the HP
//! 34401A answers `0` in its `*IDN?` serial field; an Ideal Aerosmith controller has no
//! identification command), is "not compared", never a mismatch. Serials are compared
//! without regard to case or surrounding blanks.

use super::{InstrumentRecord, Station};

/// The deviation kind of a serial that differs from the station file's.
pub const SERIAL_MISMATCH: &str = "instrument-serial-mismatch";

/// What one instrument's comparison found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SerialCheck {
    /// The instrument reports the station's serial.
    Match {
        /// `multimeter` or `table`.
        role: &'static str,
        /// The serial.
        serial: String,
    },
    /// The instrument reports another serial than the station's record.
    Mismatch {
        /// `multimeter` or `table`.
        role: &'static str,
        /// The station's asset id for it.
        asset_id: String,
        /// The station file's serial.
        expected: String,
        /// What the instrument reported.
        reported: String,
    },
    /// The chamber's controller is the one the station's record names (a chamber controller
    /// identifies itself by model; see [`Station::check_chamber`]).
    ModelMatch {
        /// `chamber`.
        role: &'static str,
        /// The model the controller reported.
        model: String,
    },
    /// The chamber's controller is another than the station's record names.
    ModelMismatch {
        /// `chamber`.
        role: &'static str,
        /// The station's asset id for it.
        asset_id: String,
        /// The station file's model.
        expected: String,
        /// The model the controller reported.
        reported: String,
    },
    /// Nothing to compare.
    NotCompared {
        /// `multimeter` or `table`.
        role: &'static str,
        /// Why, in words ("it reports no serial (0)").
        why: String,
    },
}

/// A serial as an instrument reported it, or `None` when it reports none: empty, or `0` (the
/// 34401A's serial field).
pub fn reported_serial(field: &str) -> Option<&str> {
    let s = field.trim();
    (!s.is_empty() && s != "0").then_some(s)
}

impl SerialCheck {
    /// The instrument's role.
    pub fn role(&self) -> &'static str {
        match self {
            SerialCheck::Match { role, .. }
            | SerialCheck::Mismatch { role, .. }
            | SerialCheck::ModelMatch { role, .. }
            | SerialCheck::ModelMismatch { role, .. }
            | SerialCheck::NotCompared { role, .. } => role,
        }
    }

    /// The result's name in JSON documents: `match`, `mismatch`, `model-match`,
    /// `model-mismatch`, `not-compared`.
    pub fn key(&self) -> &'static str {
        match self {
            SerialCheck::Match { .. } => "match",
            SerialCheck::Mismatch { .. } => "mismatch",
            SerialCheck::ModelMatch { .. } => "model-match",
            SerialCheck::ModelMismatch { .. } => "model-mismatch",
            SerialCheck::NotCompared { .. } => "not-compared",
        }
    }

    /// True for a mismatch of serial or (a chamber's) model: a warning and a deviation.
    pub fn is_mismatch(&self) -> bool {
        matches!(
            self,
            SerialCheck::Mismatch { .. } | SerialCheck::ModelMismatch { .. }
        )
    }

    /// The result in words, for the terminal: "the multimeter DMM-0042: the station file says
    /// serial 3146A12345 but the instrument reports SIM0001".
    pub fn words(&self, station_id: &str) -> String {
        let role = |r: &str| match r {
            "table" => "rate table",
            "chamber" => "thermal chamber",
            _ => "multimeter",
        };
        match self {
            SerialCheck::Match { role: r, serial } => format!(
                "the {}'s serial {serial} matches station {station_id}",
                role(r)
            ),
            SerialCheck::Mismatch {
                role: r,
                asset_id,
                expected,
                reported,
            } => format!(
                "the {} {asset_id}: station {station_id} says serial {expected}, but the \
                 instrument that answered reports serial {reported}: the certificate would name \
                 another instrument's calibration",
                role(r)
            ),
            SerialCheck::ModelMatch { role: r, model } => format!(
                "the {}'s controller ({model}) is the one station {station_id} names",
                role(r)
            ),
            SerialCheck::ModelMismatch {
                role: r,
                asset_id,
                expected,
                reported,
            } => format!(
                "the {} {asset_id}: station {station_id} names a {expected}, but the \
                 controller that answered is a {reported}: the certificate would name another \
                 chamber's calibration (if the chamber has that controller, name it in the \
                 station's model, e.g. \"{expected} ({reported})\")",
                role(r)
            ),
            SerialCheck::NotCompared { role: r, why } => {
                format!("the {}'s serial was not compared: {why}", role(r))
            }
        }
    }
}

impl Station {
    /// Compares the station's serials with the ones the instruments reported: `meter` and
    /// `table` are the serial fields of their identities (`None`: that instrument was not
    /// identified, or the plan drives no table, when the table is left out). See the module
    /// documentation for what counts as no serial.
    pub fn check_serials(
        &self,
        meter: Option<&str>,
        table: Option<Option<&str>>,
    ) -> Vec<SerialCheck> {
        let mut out = vec![check_one("multimeter", self.multimeter.as_ref(), meter)];
        if let Some(table) = table {
            out.push(check_one("table", self.table.as_ref(), table));
        }
        out
    }
}

fn check_one(
    role: &'static str,
    record: Option<&InstrumentRecord>,
    reported: Option<&str>,
) -> SerialCheck {
    let Some(record) = record else {
        return SerialCheck::NotCompared {
            role,
            why: format!("the station file has no [{role}] section"),
        };
    };
    let Some(raw) = reported else {
        return SerialCheck::NotCompared {
            role,
            why: "the instrument did not identify itself".into(),
        };
    };
    let Some(reported) = reported_serial(raw) else {
        return SerialCheck::NotCompared {
            role,
            why: if raw.trim().is_empty() {
                "the instrument reports no serial".into()
            } else {
                format!(
                    "the instrument reports no serial ({:?} in its identity's serial field, as \
                     an HP 34401A does)",
                    raw.trim()
                )
            },
        };
    };
    if reported.eq_ignore_ascii_case(record.serial.trim()) {
        SerialCheck::Match {
            role,
            serial: reported.to_string(),
        }
    } else {
        SerialCheck::Mismatch {
            role,
            asset_id: record.asset_id.clone(),
            expected: record.serial.trim().to_string(),
            reported: reported.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn station() -> Station {
        let src = r#"
id = "bench-2"
lab = "Lab"
address = "Road"
[multimeter]
model = "HP 34401A"
asset_id = "DMM-0042"
serial = "3146A12345"
certificate = "C1"
calibrated = 2026-01-01
due = 2099-01-01
"#;
        Station::from_toml_str_on(
            src,
            std::path::Path::new("station.toml"),
            jiff::civil::date(2026, 6, 1),
        )
        .unwrap()
    }

    #[test]
    fn a_matching_serial_ignores_case_and_blanks() {
        let c = station().check_serials(Some(" 3146a12345 "), None);
        assert_eq!(
            c,
            vec![SerialCheck::Match {
                role: "multimeter",
                serial: "3146a12345".into()
            }]
        );
    }

    #[test]
    fn another_serial_is_a_mismatch_naming_both() {
        let c = station().check_serials(Some("SIM0001"), None);
        assert!(c[0].is_mismatch());
        let w = c[0].words("bench-2");
        assert!(
            w.contains("3146A12345") && w.contains("SIM0001") && w.contains("DMM-0042"),
            "{w}"
        );
    }

    #[test]
    fn no_serial_on_either_side_is_not_compared() {
        let s = station();
        // a 34401A's serial field
        let c = s.check_serials(Some("0"), Some(Some("1120-0031")));
        assert!(matches!(&c[0], SerialCheck::NotCompared { why, .. } if why.contains("\"0\"")));
        // no [table] section
        assert!(matches!(&c[1], SerialCheck::NotCompared { why, .. } if why.contains("[table]")));
        // an Aerosmith: no identification
        let c = s.check_serials(Some(""), None);
        assert!(matches!(&c[0], SerialCheck::NotCompared { .. }));
        assert!(!c.iter().any(SerialCheck::is_mismatch));
    }
}
