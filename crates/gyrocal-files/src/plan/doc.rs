//! The document form: a plan as parsed, every default explicit, with the file's own section
//! and key names ([`PlanDoc`]). What the manifest stores and what the content hash is
//! computed from ([`Plan::hash`]; see the module docs of [`super`] for what it covers). The
//! hash of an existing plan must not change: the serialised form of every section is kept
//! byte for byte (fields in declaration order, keys added later left out at their default).

use std::path::Path;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use gyrocal_fit::acceptance::AcceptanceSpec;

use super::dmm::DmmDoc;
use super::drift::DriftDoc;
use super::section::PlanSectionDoc;
use super::simulation::Simulation;
use super::table::TableDoc;
use super::warmup::WarmupDoc;
use super::{Plan, PlanDut};

const HASH_DOMAIN: &str = "gyrocal-plan-v1\n";

/// The plan as parsed, with every default filled in: the same sections and key names as the
/// TOML file. This is what a [`Plan`] serialises to (in the manifest) and what the hash is
/// computed from. Building a [`Plan`] from it always goes through validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanDoc {
    /// `[plan]`
    pub plan: PlanSectionDoc,
    /// `[table]`
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<TableDoc>,
    /// `[dmm]`
    pub dmm: DmmDoc,
    /// `[simulation]`
    pub simulation: Simulation,
    /// `[dut]` (absent: not named in the plan). Not part of the hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dut: Option<PlanDut>,
    /// `[acceptance]` (absent: no specification). Not part of the hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceptance: Option<AcceptanceSpec>,
    /// `[drift]` (a drift plan's table role and bench orientation; absent: the defaults).
    /// Part of the hash; absent from the documents of plans that have none, so their hashes
    /// stay what they were.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftDoc>,
    /// `[warmup]` (absent: no warm-up). Part of the hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warmup: Option<WarmupDoc>,
}

impl Plan {
    /// The plan as parsed, defaults explicit (what the manifest stores).
    pub fn to_doc(&self) -> PlanDoc {
        PlanDoc {
            plan: PlanSectionDoc {
                kind: self.kind.as_str().to_string(),
                name: self.name.clone(),
                rates_dps: self.rates_dps.clone(),
                samples_per_rate: self.samples_per_rate.into(),
                settle_s: self.settle.as_secs_f64(),
                repeat: self.repeat.into(),
                whole_revolutions: self.whole_revolutions.into(),
            },
            table: self.table_given.then(|| TableDoc {
                dialect: self.table.dialect.as_str().into(),
                port: self.table.port.to_string(),
                baud: self.table.baud.into(),
                max_rate_dps: self.table.max_rate_dps,
                acceleration_dps2: self.table.acceleration_dps2,
                rate_tolerance_dps: self.table.rate_tolerance_dps,
                stability_window_s: self.table.stability_window.as_secs_f64(),
                at_rate_timeout_s: self.table.at_rate_timeout.as_secs_f64(),
            }),
            dmm: DmmDoc {
                model: self.dmm.model.as_str().into(),
                port: self.dmm.port.to_string(),
                baud: self.dmm.baud.into(),
                framing: self.dmm.framing.to_string(),
                range_v: self.dmm.range_v,
                nplc: self.dmm.nplc,
                autozero: self.dmm.autozero,
                line_hz: self.dmm.line_hz.into(),
                acquisition: self.dmm.acquisition.as_str().into(),
            },
            simulation: self.simulation.clone(),
            dut: self.dut.clone(),
            acceptance: self.acceptance.clone(),
            drift: self.drift.map(|d| DriftDoc {
                table: d.table.as_str().into(),
                axis: d.earth.map(|(a, _)| a.as_str().into()),
                latitude_deg: d.earth.map(|(_, l)| l),
            }),
            warmup: self.warmup.map(|w| WarmupDoc {
                window_s: w.window.as_secs_f64(),
                tolerance_v: w.tolerance_v,
                max_s: w.max.as_secs_f64(),
            }),
        }
    }

    /// SHA-256 (lower-case hex) of the canonical serialisation; see the module docs for what
    /// it covers (everything but the two port fields, `[dut]` and `[acceptance]`).
    pub fn hash(&self) -> String {
        let mut doc = self.to_doc();
        if let Some(t) = doc.table.as_mut() {
            t.port.clear();
        }
        doc.dmm.port.clear();
        // one plan serves many gyros, and limits can be re-evaluated: neither is the method
        doc.dut = None;
        doc.acceptance = None;
        let mut h = Sha256::new();
        h.update(HASH_DOMAIN.as_bytes());
        // Serialising plain structs of numbers, strings and bools to JSON cannot fail; an
        // empty body would still hash deterministically.
        h.update(serde_json::to_vec(&doc).unwrap_or_default());
        h.finalize().iter().map(|b| format!("{b:02x}")).collect()
    }
}

impl Serialize for Plan {
    fn serialize<Ser: serde::Serializer>(&self, s: Ser) -> Result<Ser::Ok, Ser::Error> {
        self.to_doc().serialize(s)
    }
}

impl<'de> Deserialize<'de> for Plan {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let doc = PlanDoc::deserialize(d)?;
        Plan::from_doc(doc, Path::new("plan")).map_err(serde::de::Error::custom)
    }
}
