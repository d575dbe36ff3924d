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
use super::kind::KindSectionsDoc;
use super::section::{self, PlanSectionDoc};
use super::simulation::Simulation;
use super::table::TableDoc;
use super::warmup::{WarmupDoc, WarmupSettings};
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
    /// The test kinds' own sections (`[drift]`), each under its own name at this place in
    /// the document (so the serialised form, and the hash, of every existing plan stays byte
    /// for byte what it was). Part of the hash; a section absent from the file is absent
    /// from the document.
    #[serde(flatten)]
    pub kinds: KindSectionsDoc,
    /// `[warmup]` (absent: no warm-up). Part of the hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warmup: Option<WarmupDoc>,
}

impl Plan {
    /// The plan as parsed, defaults explicit (what the manifest stores): each section's own
    /// module writes its part.
    pub fn to_doc(&self) -> PlanDoc {
        PlanDoc {
            plan: section::to_doc(self),
            table: self.table_given.then(|| self.table.to_doc()),
            dmm: self.dmm.to_doc(),
            simulation: self.simulation.clone(),
            dut: self.dut.clone(),
            acceptance: self.acceptance.clone(),
            kinds: self.kind_sections.to_doc(),
            warmup: self.warmup.map(WarmupSettings::to_doc),
        }
    }

    /// SHA-256 (lower-case hex) of the canonical serialisation; see the module docs for what
    /// it covers (everything but the port fields (the chamber's too), `[dut]` and `[acceptance]`).
    pub fn hash(&self) -> String {
        let mut doc = self.to_doc();
        if let Some(t) = doc.table.as_mut() {
            t.port.clear();
        }
        doc.dmm.port.clear();
        if let Some(c) = doc.kinds.chamber.as_mut() {
            c.port.clear();
        }
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
