//! What a plan measures ([`PlanKind`]) and the one dispatch on it in the plan crate: each
//! kind's own rules live in its module ([`super::sweep`], [`super::drift`]), its own section
//! of the file (`[drift]`) included; adding a kind is its module and this file (a variant,
//! an arm in each match below, its section's field in [`KindSectionsDoc`] and
//! [`KindSections`]). The common sections' modules (raw, document, schema, validation) reach
//! the kinds' sections only through here.

use serde::{Deserialize, Serialize};
use toml::de::DeTable;

/// **The one list of test kinds**: `module => PlanKind variant`, one entry per kind. Every crate
/// with a part of its own per kind expands it with a macro of its own (`$callback! { sweep =>
/// Sweep, drift => Drift }`), declaring one module per kind (named as here) and its one
/// dispatch on the kind (a match over the variants, generated): the plan crate's kind modules
/// (`plan/sweep.rs`, `plan/drift.rs`), the analysis crate's (`gyrocal-analysis/src/sweep.rs`,
/// `drift/`), the report crate's (`gyrocal-report/src/kinds/`). So a kind of test is added
/// here (this list, its variant and its arms in this file) and in its three modules, and in
/// no crate's `lib.rs` or `mod.rs`.
#[macro_export]
macro_rules! for_each_test_kind {
    ($callback:ident) => {
        $callback! { sweep => Sweep, drift => Drift, series => Series }
    };
}

use super::chamber::{ChamberDoc, ChamberSettings, RawChamber};
use super::drift::{DriftDoc, DriftSettings, RawDrift};
use super::error::PlanError;
use super::raw::Spans;
use super::schema::SectionSchema;
use super::series::{RawSeries, SeriesDoc, SeriesSettings};
use super::table::TableDialect;
use super::validate::Ctx;
use super::{chamber, drift, series, sweep};

/// The test kinds' own sections of the file (name, required, keys), in the order the file
/// documents them: part of the schema the file's shape is checked against.
pub(super) const SECTIONS: &[SectionSchema] = &[
    ("drift", false, drift::KEYS),
    ("series", false, series::KEYS),
    ("chamber", false, chamber::KEYS),
];

/// The kinds' own sections as written in the file, read by their modules from the same text
/// as the common sections (serde ignores the common sections here; their struct ignores
/// these).
#[derive(Deserialize)]
struct RawSections {
    drift: Option<RawDrift>,
    series: Option<RawSeries>,
    chamber: Option<RawChamber>,
}

/// Reads the kinds' own sections from the plan's text, their values' spans into `sp`. The
/// outer error is serde's; the inner one a whole-number key out of 64 bits, `(key, message)`.
pub(super) fn raw_sections(
    src: &str,
    sp: &mut Spans,
) -> Result<Result<KindSectionsDoc, (&'static str, String)>, toml::de::Error> {
    let raw: RawSections = toml::from_str(src)?;
    let drift = raw.drift.map(|d| DriftDoc::from_raw(d, sp));
    let series = match raw.series.map(|s| SeriesDoc::from_raw(s, sp)).transpose() {
        Ok(s) => s,
        Err(e) => return Ok(Err(e)),
    };
    let chamber = match raw.chamber.map(|c| ChamberDoc::from_raw(c, sp)).transpose() {
        Ok(c) => c,
        Err(e) => return Ok(Err(e)),
    };
    Ok(Ok(KindSectionsDoc {
        drift,
        series,
        chamber,
    }))
}

/// The test kinds' own sections in the document form (what the manifest stores and the hash
/// covers): one optional field per kind that has a section, flattened into the
/// [`super::PlanDoc`] at the place the document always had them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct KindSectionsDoc {
    /// `[drift]` (a drift plan's table role and bench orientation; absent: the defaults).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftDoc>,
    /// `[series]` (a temperature series' temperatures, soak criterion and measurement).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub series: Option<SeriesDoc>,
    /// `[chamber]` (the thermal chamber a temperature series drives).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber: Option<ChamberDoc>,
}

impl KindSectionsDoc {
    /// Whether the kinds' sections leave the plan without a table (`[drift] table = "none"`):
    /// then `[table]` may be left out.
    pub(super) fn uses_table(&self) -> bool {
        !drift::has_no_table(self.drift.as_ref())
    }

    /// Validates each section against the plan's `kind` (a kind's section on a plan of
    /// another kind is refused) and the table's dialect.
    pub(super) fn validate(
        self,
        kind: PlanKind,
        dialect: TableDialect,
        rates: &[f64],
        cx: &Ctx<'_>,
    ) -> Result<KindSections, PlanError> {
        let drift = drift::validate(self.drift, kind, dialect, cx)?;
        let (series, chamber) = series::validate(self.series, self.chamber, kind, rates, cx)?;
        Ok(KindSections {
            drift,
            series,
            chamber,
        })
    }
}

/// The kinds' own sections, validated.
#[derive(Debug, Clone, PartialEq, Default)]
pub(super) struct KindSections {
    pub(super) drift: Option<DriftSettings>,
    pub(super) series: Option<SeriesSettings>,
    pub(super) chamber: Option<ChamberSettings>,
}

impl KindSections {
    /// As the document writes them.
    pub(super) fn to_doc(&self) -> KindSectionsDoc {
        KindSectionsDoc {
            drift: self.drift.map(DriftSettings::to_doc),
            series: self.series.as_ref().map(SeriesSettings::to_doc),
            chamber: self.chamber.as_ref().map(ChamberSettings::to_doc),
        }
    }
}

/// Whether the file's shape (before serde) says the plan needs no `[table]`.
pub(super) fn table_optional_in(root: &DeTable<'_>) -> bool {
    drift::has_no_table_in(root)
}

/// Whether a run of `plan` uses a rate table.
pub(super) fn uses_table(plan: &super::Plan) -> bool {
    match plan.kind() {
        PlanKind::Sweep => true,
        PlanKind::Drift => plan.drift().table != drift::TableRole::None,
        PlanKind::Series => true,
    }
}

pub(super) fn default_kind() -> String {
    PlanKind::Sweep.as_str().to_string()
}

pub(super) fn is_scale_factor(kind: &str) -> bool {
    kind == PlanKind::Sweep.as_str()
}

/// What a plan measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlanKind {
    /// A sweep of rates for the scale factor (the paper's method): `kind = "scale_factor"`,
    /// the default.
    #[default]
    Sweep,
    /// A static record at zero rate (IEEE 952 §6.6 drift test) in durable segments: every
    /// rate is 0, `samples_per_rate` readings make one segment (one step) and `repeat`
    /// segments the record; analysed by Allan deviation instead of a line.
    Drift,
    /// A temperature series (IEEE 1431 §12.8): a thermal chamber set to each temperature of
    /// `[series] temperatures_c`, a soak until the gyro has settled, then the sweep, a bias
    /// record at 0 °/s or both at each: `kind = "temperature_series"`.
    Series,
}

impl PlanKind {
    /// All kinds.
    pub const ALL: [PlanKind; 3] = [PlanKind::Sweep, PlanKind::Drift, PlanKind::Series];

    /// The kind of the run whose manifest is `m` (its plan's).
    pub fn of(m: &crate::rundir::Manifest) -> PlanKind {
        m.plan.kind()
    }

    /// The kind of a run of `plan`.
    pub fn of_plan(plan: &super::Plan) -> PlanKind {
        plan.kind()
    }

    /// The kind of the run in `dir`, or `None` when `dir` is not a readable run directory (a
    /// file, a directory without a manifest, a malformed one: the caller's own reading says
    /// why).
    pub fn of_dir(dir: &std::path::Path) -> Option<PlanKind> {
        if !dir.is_dir() {
            return None;
        }
        crate::load(dir).ok().map(|r| r.manifest.plan.kind())
    }

    /// The result file the analysis of a run of this kind writes into its run directory.
    pub fn result_file(self) -> &'static str {
        match self {
            PlanKind::Sweep => crate::rundir::FIT_JSON,
            PlanKind::Drift => crate::rundir::ALLAN_JSON,
            PlanKind::Series => crate::rundir::SERIES_JSON,
        }
    }

    /// `scale_factor`, `drift` or `temperature_series`, as written in a plan.
    pub fn as_str(self) -> &'static str {
        match self {
            PlanKind::Sweep => "scale_factor",
            PlanKind::Drift => "drift",
            PlanKind::Series => "temperature_series",
        }
    }
}

/// Compiles `plan` (of this kind) for a session that runs `remaining` steps of its schedule:
/// the one dispatch on the kind for the run's engine (see [`crate::steps::compile`]).
pub(crate) fn compile(
    plan: &super::Plan,
    remaining: &[super::Step],
    warmup_done: bool,
) -> crate::steps::Compiled {
    match plan.kind() {
        PlanKind::Sweep => sweep::compile(plan, remaining, warmup_done),
        PlanKind::Drift => drift::compile(plan, remaining, warmup_done),
        PlanKind::Series => series::compile(plan, remaining, warmup_done),
    }
}

/// The schedule of `plan` (see [`super::Plan::schedule`]).
pub(super) fn schedule(plan: &super::Plan) -> Vec<super::Step> {
    match plan.kind() {
        PlanKind::Sweep | PlanKind::Drift => plan.passes_schedule(0, None),
        PlanKind::Series => series::schedule(plan),
    }
}

/// The number of steps of `plan`'s schedule.
pub(super) fn step_count(plan: &super::Plan) -> usize {
    match plan.kind() {
        PlanKind::Sweep | PlanKind::Drift => plan.passes_count(),
        PlanKind::Series => series::step_count(plan),
    }
}

/// What a kind says of itself in `gyrocal check` (its own section of the plan).
#[derive(Debug, Clone, PartialEq)]
pub struct KindSummary {
    /// The key its settings go under in `gyrocal check --json` (its section's name: `drift`).
    pub key: &'static str,
    /// One line for the terminal.
    pub line: String,
    /// Its settings for `gyrocal check --json` (under [`KindSummary::key`]).
    pub json: serde_json::Value,
}

pub(super) fn summary(plan: &super::Plan) -> Option<KindSummary> {
    match plan.kind() {
        PlanKind::Sweep => None,
        PlanKind::Drift => Some(drift::summary(&plan.drift())),
        PlanKind::Series => series::summary(plan),
    }
}

/// `[plan] kind` as written.
pub(super) fn parse(kind: &str, cx: &Ctx<'_>) -> Result<PlanKind, PlanError> {
    PlanKind::ALL
        .into_iter()
        .find(|k| k.as_str() == kind.trim())
        .ok_or_else(|| {
            cx.err(
                "plan.kind",
                format!(
                    "unknown kind {kind:?}: write \"scale_factor\" (a sweep of rates), \"drift\" (a static record at zero rate) or \"temperature_series\" (a sweep or bias record at each temperature of a thermal chamber)"
                ),
            )
        })
}

/// The kind's own rule on the rates of one pass (`rates`, validated; `written`, as in the
/// file, for the message).
pub(super) fn check_rates(
    kind: PlanKind,
    rates: &[f64],
    written: &[f64],
    cx: &Ctx<'_>,
) -> Result<(), PlanError> {
    match kind {
        PlanKind::Sweep => sweep::check_rates(rates, cx),
        PlanKind::Drift => drift::check_rates(rates, written, cx),
        // the series' rule depends on `[series] measure`: checked with its section
        PlanKind::Series => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Plan, PlanDoc};

    const DRIFT: &str = "[plan]\nkind = \"drift\"\nrates_dps = [0]\nsamples_per_rate = 10\n\
        [table]\nport = \"/dev/ttyUSB1\"\nmax_rate_dps = 20\nacceleration_dps2 = 10\n\
        [dmm]\nport = \"/dev/ttyUSB0\"\n[drift]\ntable = \"servo_off\"\n[warmup]\n";

    /// A kind's own section sits in the document where `[drift]` always sat (after
    /// `[acceptance]`, before `[warmup]`), so the serialised document, and the hash, of a
    /// drift plan are what they were before the kinds' sections moved behind this module.
    #[test]
    fn a_kinds_section_keeps_its_place_in_the_document() {
        let plan = Plan::from_toml_str(DRIFT, std::path::Path::new("drift.toml")).unwrap();
        let json = serde_json::to_string(&plan.to_doc()).unwrap();
        let drift = json.find("\"drift\":{").unwrap();
        let warmup = json.find("\"warmup\":{").unwrap();
        let simulation = json.find("\"simulation\":{").unwrap();
        assert!(simulation < drift && drift < warmup, "{json}");
        assert_eq!(plan.drift().table, super::drift::TableRole::ServoOff);
    }

    /// A document (a manifest's plan) with a section no plan has is refused, as it was when
    /// every section was a field of the document.
    #[test]
    fn a_document_with_an_unknown_section_is_refused() {
        let plan = Plan::from_toml_str(DRIFT, std::path::Path::new("drift.toml")).unwrap();
        let mut v = serde_json::to_value(plan.to_doc()).unwrap();
        v.as_object_mut()
            .unwrap()
            .insert("bogus".into(), serde_json::json!({"x": 1}));
        let back: Result<PlanDoc, _> = serde_json::from_value(v);
        assert!(back.is_err(), "{back:?}");
    }
}
