//! `[dut]`: the gyro under test, when the plan names it. Not part of the hash.

use serde::Deserialize;

use super::error::PlanError;
use super::raw::{S, Spans};
use super::schema::{KeySchema, Kind};
use super::validate::Ctx;

/// The keys of `[dut]`.
pub(super) const KEYS: &[KeySchema] = &[
    ("serial", Kind::Text, false),
    ("model", Kind::Text, false),
    ("manufacturer", Kind::Text, false),
    ("condition", Kind::Text, false),
    ("notes", Kind::Text, false),
];

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawDut {
    pub(super) serial: Option<S<String>>,
    pub(super) model: Option<S<String>>,
    pub(super) manufacturer: Option<S<String>>,
    pub(super) condition: Option<S<String>>,
    pub(super) notes: Option<S<String>>,
}

/// `[dut]`: the gyro under test, when the plan names it (a plan written for one gyro): the
/// run directory's own record ([`crate::rundir::Dut`]), every key optional text; the command
/// line overrides each key it gives ([`crate::rundir::Dut::overridden_by`]). Left out of the
/// plan's hash: one plan serves many gyros, and naming the gyro does not change the
/// measurement.
pub type PlanDut = crate::rundir::Dut;

/// `[dut]` as written, spans kept.
pub(super) fn from_raw(d: RawDut, sp: &mut Spans) -> PlanDut {
    PlanDut {
        serial: d.serial.map(|v| sp.take("dut.serial", v)),
        model: d.model.map(|v| sp.take("dut.model", v)),
        manufacturer: d.manufacturer.map(|v| sp.take("dut.manufacturer", v)),
        condition: d.condition.map(|v| sp.take("dut.condition", v)),
        notes: d.notes.map(|v| sp.take("dut.notes", v)),
    }
}

/// Checks `[dut]`: text, none of it empty (an empty section is no `[dut]`).
pub(super) fn validate(dut: Option<PlanDut>, cx: &Ctx<'_>) -> Result<Option<PlanDut>, PlanError> {
    if let Some(d) = &dut {
        for (key, v) in d.fields() {
            if v.as_ref().is_some_and(|v| v.trim().is_empty()) {
                return Err(cx.err(
                    &format!("dut.{key}"),
                    "must not be empty: leave the key out when it is not known".into(),
                ));
            }
        }
    }
    Ok(dut.filter(|d| !d.is_empty()))
}
