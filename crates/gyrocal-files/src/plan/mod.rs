//! Test plans: TOML file -> raw serde structs -> validated [`Plan`] -> [`Step`] schedule.
//!
//! Parsing happens in two stages, ripgrep-style:
//!
//! 1. **Raw**: the file is parsed into `toml`'s spanned document and its shape checked against
//!    a small schema (sections, keys, the kind of each value): a missing key is reported under
//!    its own section at that section's header, an unknown section or key gets "did you mean
//!    \[table\]?" (edit distance), a value of the wrong kind is said in words ("write a whole
//!    number from 1 to 1000000"). Then private serde structs mirror the file (`[plan]`,
//!    `[table]`, `[dmm]`, `[simulation]`), reject unknown keys (`deny_unknown_fields`) and keep
//!    the byte span of every value ([`toml::Spanned`]). TOML syntax errors are reported from
//!    `toml`'s own spans.
//! 2. **Validated**: the raw values, with defaults filled in, become a [`PlanDoc`] (the plain,
//!    serialisable form with the file's key names) and are checked against the instruments'
//!    limits. Every semantic error points at the offending value through the span kept in
//!    stage 1, so a message reads `configs/bad.toml:7:21: [table] acceleration_dps2 must be > 0
//!    (got 0)`.
//!
//! A [`Plan`] serialises (serde) as its [`PlanDoc`], so the manifest holds the plan "as parsed":
//! the file's keys, every default made explicit. Deserialising a `Plan` (from a manifest)
//! runs the same validation, so nothing read back from disk is trusted.
//!
//! # The content hash
//!
//! [`Plan::hash`] is the SHA-256 (hex) of a canonical serialisation of the *validated* plan, not
//! of the file bytes: comments, whitespace, key order, `0` versus `0.0`, `-0` versus `0` and
//! spelled-out defaults do not change it; any change of a rate, a setting or the simulated truth
//! does. The canonical form is the compact JSON of the [`PlanDoc`] (fields in declaration
//! order, numbers in shortest round-trip form) prefixed with `gyrocal-plan-v1\n`, with the
//! two serial/TCP port fields left out: where an instrument is plugged in does not change the
//! measurement, and an operator who moved a USB adapter must still be able to resume.
//! The optional `[dut]` (the gyro under test) and `[acceptance]` (the specification and its
//! decision rule) sections are left out too: one plan serves many gyros, and limits can be
//! re-evaluated after the run (`gyrocal report RUN --acceptance FILE`), so neither changes the
//! method, the hash, or whether a run resumes. Both are kept in the [`PlanDoc`] (and so in
//! the manifest) when present.
//!
//! # Acceptance files
//!
//! [`load_acceptance`] reads a standalone file whose top level is what `[acceptance]` holds
//! (module `acceptance`).
//!
//! # Where things are
//!
//! One module per concern, so a key's schema entry, raw field, default and checks sit
//! together in its section's module:
//!
//! - stage 1: `source` (reading, line and column), `words` (did-you-mean, word lists),
//!   `schema` (sections and keys, the shape check), `raw` (the serde structs' assembly and
//!   spans);
//! - the document form and the hash: `doc`;
//! - stage 2: `validate` (the order of the sections, the error context), then one module
//!   per section: `section` (`[plan]`), `table` and `dmm` (the bench's instruments; a port is the
//!   link's own type, [`Port`]), `simulation` (the simulated truth), `dut`, `acceptance`;
//! - one module per test kind, with `kind` the one dispatch on it: `sweep`
//!   (`scale_factor`), `drift` (with its `[drift]` section) and `series`
//!   (`temperature_series`, with its `[series]` section and the chamber's `[chamber]`, module
//!   `chamber`); `warmup` (`[warmup]`, any kind);
//! - the schedule a plan expands into: `schedule`.

mod acceptance;
mod chamber;
mod dmm;
mod doc;
mod dut;
mod error;
mod kind;
mod raw;
mod schedule;
mod schema;
mod section;
mod simulation;
mod source;
mod table;
mod validate;
mod warmup;
mod words;

// The test kinds' modules (`sweep`, `drift`), one per entry of the one list of kinds
// ([`crate::for_each_test_kind`], in `kind.rs`).
macro_rules! kind_modules {
    ($($module:ident => $variant:ident),* $(,)?) => {
        $(mod $module;)*
    };
}
crate::for_each_test_kind!(kind_modules);

use std::path::Path;
use std::time::Duration;

use gyrocal_fit::acceptance::AcceptanceSpec;
use toml::de::DeTable;

pub use acceptance::{acceptance_from_toml_str, load_acceptance};
pub use chamber::{
    AlarmRegisterDoc, AlarmRegisterSetting, CHAMBER_BAUDS, ChamberDoc, ChamberModel,
    ChamberSettings, DEFAULT_AMBIENT_C, DEFAULT_CHAMBER_BAUD, DEFAULT_MAX_C, DEFAULT_MIN_C,
    DEFAULT_RAMP_C_PER_MIN, SafeStateChoice,
};
pub use dmm::{
    Acquisition, DmmDoc, DmmModel, DmmSettings, Framing, KNOWN_NPLC_VALUES, LINE_HZ, NPLC_VALUES,
    RANGES_V,
};
pub use doc::PlanDoc;
pub use drift::{Axis, DriftDoc, DriftSettings, EARTH_RATE_DPH, TableRole};
pub use dut::PlanDut;
pub use error::{Location, PlanError, PlanErrorKind};
/// Where an instrument is connected: the link's own type, parsed once when the plan is
/// validated (`tcp://HOST:PORT`, `prologix:DEVICE?addr=N`, `prologix-tcp://HOST?addr=N` or a
/// serial device path); nothing downstream parses the string again.
pub use gyrocal_link::PortSpec as Port;
pub(crate) use kind::compile;
pub use kind::{KindSectionsDoc, KindSummary, PlanKind};
pub use schedule::{Acquire, SeriesStep, Step};
pub use section::{MAX_REPEAT, MAX_SAMPLES_PER_RATE, MAX_WHOLE_REVOLUTIONS, PlanSectionDoc};
pub use series::{
    DEFAULT_BAND_C, DEFAULT_BIAS_READINGS, DEFAULT_MAX_WAIT_MIN, DEFAULT_POLL_S, DEFAULT_SOAK_MIN,
    DEFAULT_STABILITY_C_PER_MIN, MAX_SOAK_MIN, MAX_TEMPERATURES, Measure, SeriesDoc,
    SeriesSettings, ramps_and_soaks,
};
pub use simulation::Simulation;
pub use source::MAX_PLAN_BYTES;
pub(crate) use source::{ReadFailure, read_capped_text};
pub use table::{
    HARD_MAX_ACCELERATION_DPS2, HARD_MAX_RATE_DPS, TableDialect, TableDoc, TableSettings,
};
pub use warmup::{
    DEFAULT_WARMUP_MAX_S, DEFAULT_WARMUP_SIGMAS, DEFAULT_WARMUP_WINDOW_S, WarmupDoc, WarmupSettings,
};
pub(crate) use words::{and_list, closest};

use error::PLAN_DOCUMENT;
use raw::{RawFile, Spans, raw_to_doc};
use schema::{check_shape, finding_error, plain_words};

/// The names of a plan file's sections (`plan`, `table`, ..., the test kinds' own), in the
/// order the file documents them.
pub(crate) fn section_names() -> impl Iterator<Item = &'static str> {
    schema::schema().map(|s| s.0)
}
use source::{read_document, section_at};
use validate::{Ctx, validate};

/// Upper bound for every duration key (`settle_s`, `stability_window_s`, `at_rate_timeout_s`):
/// one day.
pub const MAX_DURATION_S: f64 = 86_400.0;
// The instruments' facts are their crates' (one copy each, built without I/O for this
// synchronous crate); the plan checks against them.

/// Baud rates the HP 34401A offers (also accepted for the table's serial link): the link's.
pub use gyrocal_link::facts::SUPPORTED_BAUDS as BAUD_RATES;

/// A validated test plan. Built only by [`Plan::from_toml_str`], [`Plan::from_file`] or
/// [`Plan::from_doc`], so its invariants hold; serialises (serde) as its [`PlanDoc`].
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    kind: PlanKind,
    name: String,
    rates_dps: Vec<f64>,
    samples_per_rate: u32,
    settle: Duration,
    repeat: u32,
    whole_revolutions: u32,
    table: TableSettings,
    dmm: DmmSettings,
    simulation: Simulation,
    dut: Option<PlanDut>,
    acceptance: Option<AcceptanceSpec>,
    /// The test kinds' own sections, validated (`[drift]`).
    kind_sections: kind::KindSections,
    warmup: Option<WarmupSettings>,
    /// The file had a `[table]` section (without one, `[drift] table = "none"`: `table` holds
    /// [`TableDoc::unused`]'s settings, which nothing reads).
    table_given: bool,
}

impl Plan {
    /// Reads and validates a plan file; errors name `path`.
    /// A file larger than [`MAX_PLAN_BYTES`] is refused after reading at most that much.
    pub fn from_file(path: &Path) -> Result<Plan, PlanError> {
        let src = read_document(path, PLAN_DOCUMENT)?;
        Plan::from_toml_str(&src, path)
    }

    /// Parses and validates plan text; `origin` is the file name used in errors.
    pub fn from_toml_str(src: &str, origin: &Path) -> Result<Plan, PlanError> {
        let location = |offset: Option<usize>| Location::in_text(origin, src, offset);
        let syntax = |e: toml::de::Error| {
            let offset = e.span().map(|span| span.start);
            PlanError::Syntax {
                location: location(offset),
                section: offset.and_then(|o| section_at(src, o)),
                message: plain_words(e.message().trim()),
            }
        };
        // The shape first (sections, keys, kinds of value), so a missing key names its own
        // section and a wrong type is said in words; then serde, with the spans.
        let root = DeTable::parse(src).map_err(syntax)?;
        let mut findings = check_shape(root.get_ref());
        findings.sort_by_key(|f| (f.rank, f.offset.unwrap_or(usize::MAX)));
        if let Some(f) = findings.into_iter().next() {
            return Err(finding_error(f, location));
        }
        let raw: RawFile = toml::from_str(src).map_err(syntax)?;
        let mut spans = Spans::default();
        let kinds = kind::raw_sections(src, &mut spans).map_err(syntax)?;
        let doc = kinds.and_then(|kinds| raw_to_doc(raw, kinds, &mut spans));
        let cx = Ctx {
            origin,
            src: Some(src),
            spans: &spans,
        };
        validate(doc.map_err(|(key, message)| cx.err(key, message))?, &cx)
    }

    /// Validates a plain document (e.g. read back from a manifest); errors carry `origin`
    /// without a line.
    pub fn from_doc(doc: PlanDoc, origin: &Path) -> Result<Plan, PlanError> {
        validate(
            doc,
            &Ctx {
                origin,
                src: None,
                spans: &Spans::default(),
            },
        )
    }

    /// Free-text name.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// What the plan measures.
    pub fn kind(&self) -> PlanKind {
        self.kind
    }
    /// What `gyrocal check` says of the plan's kind beyond the schedule (its own section),
    /// written by the kind's module; `None` for a kind with nothing to add (a sweep).
    pub fn kind_summary(&self) -> Option<KindSummary> {
        kind::summary(self)
    }

    /// Rates of one pass, in the order applied, °/s.
    pub fn rates_dps(&self) -> &[f64] {
        &self.rates_dps
    }
    /// Readings per rate (for zero-rate and non-revolution steps).
    pub fn samples_per_rate(&self) -> u32 {
        self.samples_per_rate
    }
    /// Dwell after "at rate", before acquiring.
    pub fn settle(&self) -> Duration {
        self.settle
    }
    /// Passes over the schedule.
    pub fn repeat(&self) -> u32 {
        self.repeat
    }
    /// Whole turns per non-zero rate (0: off).
    pub fn whole_revolutions(&self) -> u32 {
        self.whole_revolutions
    }
    /// `[table]`.
    pub fn table(&self) -> &TableSettings {
        &self.table
    }
    /// `[dmm]`.
    pub fn dmm(&self) -> &DmmSettings {
        &self.dmm
    }
    /// Whether the run uses a rate table (every plan but a drift record with
    /// `[drift] table = "none"`): the plan's kind says.
    pub fn has_table(&self) -> bool {
        kind::uses_table(self)
    }
    /// `[warmup]`, when the plan asks for a warm-up.
    pub fn warmup(&self) -> Option<&WarmupSettings> {
        self.warmup.as_ref()
    }
    /// `[simulation]`.
    pub fn simulation(&self) -> &Simulation {
        &self.simulation
    }
    /// `[dut]`, when the plan names the gyro (a `[dut]` section without keys is `None`).
    pub fn dut(&self) -> Option<&PlanDut> {
        self.dut.as_ref()
    }
    /// `[acceptance]`, when the plan has a specification.
    pub fn acceptance(&self) -> Option<&AcceptanceSpec> {
        self.acceptance.as_ref()
    }
    /// Overrides the table's port (`--table-port`); ports are not part of the hash.
    pub fn set_table_port(&mut self, port: Port) {
        self.table.port = port;
    }
    /// Overrides the multimeter's port (`--dmm-port`); ports are not part of the hash.
    pub fn set_dmm_port(&mut self, port: Port) {
        self.dmm.port = port;
    }
}
