//! The station's thermal chamber: which instruments a plan needs ([`Needs`], so the
//! missing-sections and overdue rules are written once for the table and the chamber), and
//! the chamber's record against the controller that answered ([`Station::check_chamber`]).
//!
//! Why the model and not only the serial: a chamber controller has no serial to ask for (a
//! Watlow F4's registers hold none; an Espec's `TYPE?` names its model), so the identity the
//! chamber role gets is the controller's model. The station's record names the chamber as the
//! lab knows it ("Thermotron SE-600 (Watlow F4)", "Espec SH-641"); the controller that answered
//! must be the one the record names: its maker or its model number must appear in the
//! record's model. A record naming another controller (an Espec on a port the station says is
//! a Watlow) is a mismatch: a warning and a recorded deviation, since the certificate would
//! name another chamber's calibration. A reported serial, when a later controller has one, is
//! compared as the meter's and the table's are.

use super::serials::{SerialCheck, reported_serial};
use super::{Overdue, Station};
use crate::plan::{ChamberModel, Plan};

/// The plan kind that drives a chamber (`kind = "temperature_series"`).
pub const SERIES_KIND: &str = "temperature_series";

/// The instruments a run needs records of, beside the multimeter every run reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Needs {
    /// A rate table (every plan but a drift record on a bench without one).
    pub table: bool,
    /// A thermal chamber (a temperature series).
    pub chamber: bool,
}

impl Needs {
    /// What a run of `plan` needs: the table when it drives one, the chamber when it has a
    /// `[chamber]` (a temperature series).
    pub fn of_plan(plan: &Plan) -> Needs {
        Needs {
            table: plan.has_table(),
            chamber: plan.chamber().is_some(),
        }
    }

    /// Whether a run with these needs uses the instrument of `role` (`multimeter` always).
    pub fn uses(self, role: &str) -> bool {
        match role {
            "table" => self.table,
            "chamber" => self.chamber,
            _ => true,
        }
    }
}

impl Station {
    /// The simulated bench's station for a run of `plan` (`gyrocal run --simulate`):
    /// [`Station::simulated`], with a simulated chamber's record naming the plan's controller
    /// when the plan has a `[chamber]` ([`Station::simulated_with_chamber`]).
    pub fn simulated_for(seed: u64, today: jiff::civil::Date, plan: &Plan) -> Station {
        match plan.chamber() {
            Some(c) => Station::simulated_with_chamber(seed, today, controller_name(c.model)),
            None => Station::simulated(seed, today),
        }
    }

    /// The instruments a run with `needs` uses whose calibration has expired on `today` (see
    /// [`Station::overdue`]): a drift record without a table is not refused for the table's
    /// calibration, nor a sweep for the chamber's.
    pub fn overdue_for(&self, today: jiff::civil::Date, needs: Needs) -> Vec<Overdue> {
        self.overdue(today)
            .into_iter()
            .filter(|o| needs.uses(o.role))
            .collect()
    }

    /// The station's `[chamber]` record against the controller that answered: `model` its
    /// identity's model (`Watlow F4`), `serial` what it reports as a serial (`None`: none, as
    /// both dialects today). See the module documentation for the rule.
    pub fn check_chamber(&self, model: Option<&str>, serial: Option<&str>) -> Vec<SerialCheck> {
        let role = "chamber";
        let Some(record) = self.chamber.as_ref() else {
            return vec![SerialCheck::NotCompared {
                role,
                why: "the station file has no [chamber] section".into(),
            }];
        };
        let mut out = Vec::new();
        match model.map(str::trim).filter(|m| !m.is_empty()) {
            None => out.push(SerialCheck::NotCompared {
                role,
                why: "the controller did not identify itself".into(),
            }),
            Some(m) if names_controller(&record.model, m) => out.push(SerialCheck::ModelMatch {
                role,
                model: m.to_string(),
            }),
            Some(m) => out.push(SerialCheck::ModelMismatch {
                role,
                asset_id: record.asset_id.clone(),
                expected: record.model.trim().to_string(),
                reported: m.to_string(),
            }),
        }
        match serial.and_then(reported_serial) {
            None => out.push(SerialCheck::NotCompared {
                role,
                why: "the controller reports no serial (a Watlow F4 has no serial register, an \
                      Espec's TYPE? names its model only)"
                    .into(),
            }),
            Some(s) if s.eq_ignore_ascii_case(record.serial.trim()) => {
                out.push(SerialCheck::Match {
                    role,
                    serial: s.to_string(),
                });
            }
            Some(s) => out.push(SerialCheck::Mismatch {
                role,
                asset_id: record.asset_id.clone(),
                expected: record.serial.trim().to_string(),
                reported: s.to_string(),
            }),
        }
        out
    }
}

/// The controller of a plan's chamber model, as its identity names it (`Watlow F4`, `Espec`).
fn controller_name(model: ChamberModel) -> &'static str {
    match model {
        ChamberModel::WatlowF4 => "Watlow F4",
        ChamberModel::Espec => "Espec",
    }
}

/// Letters and digits only, lower case: `SH-641` and `sh641` are one model number.
fn squash(s: &str) -> String {
    s.chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// Whether the station's `record` model names the controller `identified`: its maker (the
/// identity's first word) or its model number (the identity's other words, together) appears
/// in the record, letters and digits compared without case.
fn names_controller(record: &str, identified: &str) -> bool {
    let record = squash(record);
    let mut words = identified.split_whitespace();
    let maker = words.next().map(squash).unwrap_or_default();
    let number: String = words.map(squash).collect();
    (!maker.is_empty() && record.contains(&maker))
        || (!number.is_empty() && record.contains(&number))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_names_its_controller_by_maker_or_model_number() {
        assert!(names_controller(
            "Thermotron SE-600 (Watlow F4)",
            "Watlow F4"
        ));
        assert!(names_controller("SH-641", "Espec SH-641"));
        assert!(names_controller("ESPEC sh641", "Espec SH-641"));
        assert!(!names_controller("Espec SH-641", "Watlow F4"));
        assert!(!names_controller("Thermotron SE-600", "Watlow F4"));
        assert!(!names_controller("Watlow F4", ""));
    }

    #[test]
    fn the_series_kind_is_the_plans() {
        assert_eq!(SERIES_KIND, crate::plan::PlanKind::Series.as_str());
    }

    #[test]
    fn the_identities_the_drivers_give_name_the_simulated_records_controller() {
        // gyrocal-chamber's connect() identities (watlow/mod.rs, espec.rs)
        assert!(names_controller(
            &format!("{} (simulated)", controller_name(ChamberModel::WatlowF4)),
            "Watlow F4"
        ));
        assert!(names_controller(
            &format!("{} (simulated)", controller_name(ChamberModel::Espec)),
            "Espec (SH-641/SU text protocol, experimental)"
        ));
    }

    #[test]
    fn needs_say_which_roles_a_run_uses() {
        let sweep = Needs {
            table: true,
            chamber: false,
        };
        assert!(sweep.uses("multimeter") && sweep.uses("table") && !sweep.uses("chamber"));
        let drift_alone = Needs::default();
        assert!(!drift_alone.uses("table"));
    }
}
