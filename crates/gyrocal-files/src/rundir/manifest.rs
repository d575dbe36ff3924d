//! `manifest.json`: the run's state, plan, instruments, times and the references to its
//! results ([`Manifest`] and its parts), replaced atomically at every change and read back
//! (format 1 and 2).
#[allow(unused_imports)]
use super::*;

/// State of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// In progress (or the program died: a resume finds out).
    Running,
    /// Every step done and the run closed.
    Complete,
    /// Stopped by the operator (Ctrl-C, SIGTERM).
    Aborted,
    /// Stopped by an error; the reason says which.
    Failed,
}

/// The instruments' identities (`*IDN?` replies), filled by the caller.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Instruments {
    /// The multimeter's identity.
    pub dmm: Option<String>,
    /// The rate table's identity.
    pub table: Option<String>,
}

/// The chamber of a run with one (a temperature series), in the manifest.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ChamberRecord {
    /// Who the controller said it is, and where it is connected.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<String>,
    /// The safe state the last session left it in, in words (`setpoint 23 °C (ambient), in
    /// control`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safe_state: Option<String>,
    /// Whether that state was read back from the chamber; `false`: it could NOT be
    /// confirmed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safe_confirmed: Option<bool>,
    /// What was read back, or why nothing could be.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safe_detail: Option<String>,
}

/// A resume of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Resume {
    /// Wall-clock time of the resume, RFC 3339 UTC.
    pub at_utc: String,
    /// The first step not done, where the run continues (`None`: all steps were done).
    pub from_step: Option<usize>,
    /// Steps kept.
    pub steps_done: usize,
    /// Rows of the partial step dropped from samples.csv.
    pub samples_dropped: u64,
    /// Bytes of torn last lines dropped (both CSV files).
    pub torn_bytes_dropped: u64,
    /// The manifest's status before the resume, with its reason.
    pub previous_status: Status,
    /// The previous reason, if any.
    pub previous_reason: Option<String>,
}

/// A retry logged by the sequencer (per the drivers' recovery).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Retry {
    /// Run clock, s.
    pub t_s: f64,
    /// Step in progress, if any.
    pub step: Option<usize>,
    /// `dmm` or `table`.
    pub instrument: String,
    /// What failed and what was done.
    pub message: String,
}

/// Timing figures of the schedule of the last session (the physical bound versus the time the
/// schedule took). Not the run's elapsed time: see [`Manifest::elapsed_s`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// The physical lower bound of the schedule's duration, s.
    pub bound_s: f64,
    /// The schedule of the last session on the run clock, s: from the first rate demanded to
    /// the stop command after the last step. Without connecting, identifying and configuring
    /// the instruments before it and the wait for the table's rest after it, which
    /// [`Manifest::elapsed_s`] includes. Written as `schedule_elapsed_s` (manifests of format 1
    /// called it `elapsed_s`, still read).
    #[serde(rename = "schedule_elapsed_s", alias = "elapsed_s")]
    pub elapsed_s: f64,
    /// `schedule_elapsed_s / bound_s`.
    pub ratio: f64,
    /// The acquisition strategy actually used (`stream`, `memory`, `poll`).
    pub acquisition: Option<String>,
}

/// What the caller knows when it creates a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunMeta {
    /// gyrocal's version (`env!("CARGO_PKG_VERSION")` of the CLI).
    pub gyrocal_version: String,
    /// Instrument identities, if already known (else set them later).
    pub instruments: Instruments,
    /// Whether the run uses the simulated bench.
    pub simulated: bool,
    /// Whether the run clock is virtual (the simulated bench in virtual time): see
    /// [`Manifest::virtual_time`].
    pub virtual_time: bool,
    /// The gyro under test, as the operator entered it.
    pub dut: Option<Dut>,
    /// Who ran it, for whom, and in what environment, as entered.
    pub context: Option<RunContext>,
    /// The station: the lab, the bench and its instruments' records (asset ids, serials,
    /// calibration certificates, due dates, accuracy classes), from the station file.
    pub station: Option<crate::station::Station>,
}

/// The gyro under test. Not part of the plan (one plan serves many gyros): the operator names
/// it per run; a resume refuses another serial.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dut {
    /// Serial number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub serial: Option<String>,
    /// Model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Manufacturer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub manufacturer: Option<String>,
    /// Condition as received (ISO/IEC 17025 §7.8.2.1 g), e.g. "new, no visible damage".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub condition: Option<String>,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub notes: Option<String>,
}

impl Dut {
    /// `(key, value)` of every key, in the order a plan's `[dut]` lists them.
    pub(crate) fn fields(&self) -> [(&'static str, &Option<String>); 5] {
        [
            ("serial", &self.serial),
            ("model", &self.model),
            ("manufacturer", &self.manufacturer),
            ("condition", &self.condition),
            ("notes", &self.notes),
        ]
    }

    /// Whether nothing is known about the gyro.
    pub fn is_empty(&self) -> bool {
        self.serial.is_none()
            && self.model.is_none()
            && self.manufacturer.is_none()
            && self.condition.is_none()
            && self.notes.is_none()
    }

    /// `self` with every field `over` sets replaced by `over`'s (the command line over the
    /// plan's `[dut]`).
    pub fn overridden_by(self, over: Dut) -> Dut {
        Dut {
            serial: over.serial.or(self.serial),
            model: over.model.or(self.model),
            manufacturer: over.manufacturer.or(self.manufacturer),
            condition: over.condition.or(self.condition),
            notes: over.notes.or(self.notes),
        }
    }
}

/// A departure from the method, recorded when it happens (ISO/IEC 17025 §7.8.2.1 n): for
/// example a run started with an instrument whose calibration was overdue
/// (`--allow-expired`). The report lists these with the deviations it derives from the
/// manifest itself (resumes, retries, a simulated bench).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Deviation {
    /// A short machine-readable kind, e.g. `expired-calibration`.
    pub kind: String,
    /// What happened, in words.
    pub text: String,
    /// When it was recorded, RFC 3339 UTC.
    pub at_utc: String,
}

/// Who ran a run, for whom, and the environment as entered (not measured).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunContext {
    /// The operator.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub operator: Option<String>,
    /// The customer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub customer: Option<String>,
    /// Ambient temperature, °C.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ambient_c: Option<f64>,
    /// Relative humidity, %.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub humidity_pct: Option<f64>,
}

/// What the manifest says about the fit: a reference to `fit.json` and the headline figures
/// an index of runs needs. The fit itself (every model, residuals, the error surface) lives
/// only in `fit.json`, which can be large.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitSummary {
    /// The fit document's file name in the run directory ([`FIT_JSON`]).
    pub file: String,
    /// SHA-256 (lower-case hex) of that file's bytes as written: a `fit.json` edited or
    /// replaced afterwards no longer matches.
    pub sha256: String,
    /// Scale factor K of the least-squares line, V/(°/s).
    pub scale_factor: f64,
    /// Standard error of K, V/(°/s) (absent without degrees of freedom).
    pub scale_factor_std_error: Option<f64>,
    /// Bias K0 of the least-squares line, V.
    pub bias_volts: f64,
    /// Standard error of K0, V.
    pub bias_std_error: Option<f64>,
    /// The model chosen by the fit's model selection (nested F-test), if any.
    pub best_model: Option<gyrocal_fit::Model>,
}

impl FitSummary {
    /// The summary of `fit`, whose document's bytes hash to `sha256`.
    pub fn of(fit: &gyrocal_fit::Analysis, sha256: String) -> FitSummary {
        let line = fit.fit(
            gyrocal_fit::Method::LeastSquares,
            gyrocal_fit::Model::Linear,
        );
        FitSummary {
            file: FIT_JSON.to_string(),
            sha256,
            scale_factor: round_significant(fit.metrics.scale_factor),
            scale_factor_std_error: round_opt(line.and_then(|l| l.std_errors.k1)),
            bias_volts: round_significant(fit.metrics.bias_volts),
            bias_std_error: round_opt(line.and_then(|l| l.std_errors.k0)),
            best_model: fit.best_model,
        }
    }
}

/// The warm-up (IEEE 1431 §12.6) as a run found it online: consecutive window means of the
/// readings at rest, complete when two agree within the tolerance (or at the maximum). Before a
/// scale-factor sweep its readings are not kept (only the window means, here); in a drift run
/// they are the start of the record, and the Allan analysis cuts them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarmupRecord {
    /// `before_sweep` (a phase of its own before the first step) or `in_record` (the first
    /// segments of a drift record).
    pub mode: String,
    /// Window of the rolling mean, s.
    pub window_s: f64,
    /// The tolerance in force, V (`None` until it could be estimated).
    pub tolerance_v: Option<f64>,
    /// Where the tolerance came from: `plan` or the white-noise estimate.
    pub tolerance_source: String,
    /// The maximum, s.
    pub max_s: f64,
    /// Run-clock time of the warm-up's first reading, s.
    pub started_s: f64,
    /// The warm-up is over.
    pub complete: bool,
    /// Warm-up time, s from `started_s` (when complete).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
    /// `criterion` or `max` (when complete).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended_by: Option<String>,
    /// The change between the last two window means, V.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_change_v: Option<f64>,
    /// Window means `[run-clock time of the window's middle, s; mean, V]`, thinned to a few
    /// hundred points.
    pub means: Vec<[f64; 2]>,
}

/// `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// [`FORMAT_VERSION`].
    pub format_version: u32,
    /// Run state.
    pub status: Status,
    /// Why it is `aborted` or `failed` (or a note for `complete`).
    pub reason: Option<String>,
    /// gyrocal's version.
    pub gyrocal_version: String,
    /// SHA-256 of the plan ([`Plan::hash`]).
    pub plan_hash: String,
    /// The plan as parsed, defaults explicit (validated again when read). Written with the
    /// `[plan]` section's keys at the top (`plan.name`, `plan.rates_dps`, ...) and the other
    /// sections beside them (`plan.table`, `plan.dmm`, `plan.simulation`); a manifest of
    /// format 1 nested the `[plan]` section (`plan.plan.name`) and still reads.
    #[serde(with = "manifest_plan")]
    pub plan: Plan,
    /// Whether the run uses a simulated bench: the in-process one (`gyrocal run --simulate`),
    /// or instruments that identify themselves as simulators (`gyrocal sim`; see
    /// [`SIMULATOR_SERIAL_PREFIX`] and `simulated_by`).
    pub simulated: bool,
    /// Who said the run is simulated when it was not started with `--simulate`: the
    /// instruments' identities (a run against `gyrocal sim`). Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulated_by: Option<String>,
    /// Whether a session of the run ran the simulated bench in virtual time: the run clock
    /// (`elapsed_s`, every `t_s`, and the `t_utc` derived from it) then counts the time a
    /// real bench would have taken, and `ended_utc` is on that clock too (`started_utc` plus
    /// the run clock, like the stamps: ahead of the wall clock), while `updated_utc` is the
    /// wall clock of the last write. Absent (false) in manifests of format 1.
    #[serde(default)]
    pub virtual_time: bool,
    /// The gyro under test, as entered (absent: not named).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dut: Option<Dut>,
    /// Operator, customer and environment, as entered (absent: not given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context: Option<RunContext>,
    /// The station and its instruments' calibration records, from the station file (absent:
    /// no station file; the report then says the instruments are not identified).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub station: Option<crate::station::Station>,
    /// Instrument identities.
    pub instruments: Instruments,
    /// Departures from the method recorded during the run, oldest first (absent: none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub deviations: Vec<Deviation>,
    /// Wall-clock start, RFC 3339 UTC.
    pub started_utc: String,
    /// The end (set when the run stops), RFC 3339 UTC: the wall clock, or in virtual time
    /// the run clock's end on the clock of the `t_utc` stamps (see `virtual_time`).
    pub ended_utc: Option<String>,
    /// Wall-clock time of the last manifest write, RFC 3339 UTC.
    pub updated_utc: String,
    /// The run clock at the last write, s: the run's elapsed time, every session from
    /// connecting to the instruments to the table at rest, added up over the resumes. It is
    /// the time base of every `t_s`. The schedule alone is `timing.schedule_elapsed_s`.
    pub elapsed_s: f64,
    /// Steps in the schedule.
    pub steps_total: usize,
    /// Indices of the finished steps, ascending.
    pub steps_done: Vec<usize>,
    /// Resumes, oldest first.
    pub resumes: Vec<Resume>,
    /// Retries, oldest first.
    pub retries: Vec<Retry>,
    /// Bound versus elapsed of the last session's schedule, when it completed.
    pub timing: Option<Timing>,
    /// The verdict against the plan's acceptance limits, as in `fit.json` (absent: no limits,
    /// or not fitted yet).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub acceptance: Option<gyrocal_fit::acceptance::Acceptance>,
    /// The fit's reference and headline figures, when fitted; the fit is in `fit.json`.
    #[serde(default)]
    pub fit_summary: Option<FitSummary>,
    /// The warm-up as the run found it while recording (plans with `[warmup]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warmup: Option<WarmupRecord>,
    /// The thermal chamber of a temperature series: who it is and where the run left it
    /// (absent: the run has no chamber).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chamber: Option<ChamberRecord>,
    /// SHA-256 (lower-case hex) of the data files as they were when the run completed
    /// (`samples.csv`, `steps.csv`; `fit.json`'s is in `fit_summary`), so a file edited
    /// afterwards is found (`gyrocal verify`). Empty until the run completes, and in runs of
    /// earlier versions.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub checksums: BTreeMap<String, String>,
    /// The whole fit as manifests of format 1 embedded it (key `fit`): read, never written.
    /// A fit this version cannot read back is `None` here, with a warning: `fit.json` beside
    /// the manifest is the source of truth (see [`load_fit`]).
    #[serde(
        default,
        rename = "fit",
        deserialize_with = "lenient_fit",
        skip_serializing
    )]
    pub legacy_fit: Option<gyrocal_fit::Analysis>,
}

/// The manifest's plan: the [`crate::PlanDoc`] with the `[plan]` section's keys lifted to the
/// top (no `plan.plan.name`). Reading accepts both shapes.
mod manifest_plan {
    use std::path::Path;

    use serde::de::Error as _;
    use serde::ser::Error as _;
    use serde::{Deserialize as _, Deserializer, Serialize as _, Serializer};
    use serde_json::{Map, Value};

    use crate::plan::{Plan, PlanDoc};

    /// The sections that stay sections (the plan schema's, the test kinds' own included);
    /// every other key belongs to `[plan]`.
    fn sections() -> impl Iterator<Item = &'static str> {
        crate::plan::section_names().filter(|&s| s != "plan")
    }

    pub(super) fn serialize<S: Serializer>(plan: &Plan, s: S) -> Result<S::Ok, S::Error> {
        let doc = serde_json::to_value(plan.to_doc()).map_err(S::Error::custom)?;
        let Value::Object(mut doc) = doc else {
            return Err(S::Error::custom("a plan serialises to a JSON object"));
        };
        let mut out = match doc.remove("plan") {
            Some(Value::Object(section)) => section,
            _ => return Err(S::Error::custom("a plan has a [plan] section")),
        };
        for key in sections() {
            if let Some(v) = doc.remove(key) {
                out.insert(key.to_string(), v);
            }
        }
        // a section a later plan format adds stays a section
        out.extend(doc);
        Value::Object(out).serialize(s)
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Plan, D::Error> {
        let value = Value::deserialize(d)?;
        let Value::Object(mut obj) = value else {
            return Err(D::Error::custom("`plan` must be an object"));
        };
        let nested = matches!(obj.get("plan"), Some(Value::Object(_)));
        let doc = if nested {
            // format 1: the TOML document's shape
            Value::Object(obj)
        } else {
            let mut doc = Map::new();
            for key in sections() {
                if let Some(v) = obj.remove(key) {
                    doc.insert(key.to_string(), v);
                }
            }
            doc.insert("plan".to_string(), Value::Object(obj));
            Value::Object(doc)
        };
        let doc: PlanDoc =
            serde_json::from_value(doc).map_err(|e| D::Error::custom(format!("plan: {e}")))?;
        Plan::from_doc(doc, Path::new("manifest.json: plan")).map_err(D::Error::custom)
    }
}

/// Reads the manifest's fit, or `None` (with a warning) when it is not an analysis this
/// version understands: an unreadable fit must never make a run directory unreadable.
pub(super) fn lenient_fit<'de, D>(de: D) -> Result<Option<gyrocal_fit::Analysis>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    let value = Option::<serde_json::Value>::deserialize(de)?;
    Ok(value.and_then(|v| match serde_json::from_value(v) {
        Ok(a) => Some(a),
        Err(e) => {
            tracing::warn!(error = %e, "the manifest's fit is not readable by this version; ignored");
            None
        }
    }))
}

/// A run directory read back by [`load`].
#[derive(Debug, Clone, PartialEq)]
pub struct RunData {
    /// The manifest.
    pub manifest: Manifest,
    /// The finished steps, in file order.
    pub steps: Vec<StepRecord>,
}

/// Replaces the manifest of `dir` with `m` (its `updated_utc` set to now), atomically.
pub(super) fn store_manifest(dir: &Path, m: &mut Manifest) -> Result<(), RunError> {
    m.updated_utc = now_utc();
    let bytes = serde_json::to_vec_pretty(m).map_err(|e| RunError::Protocol {
        path: dir.join(MANIFEST_JSON),
        message: format!("cannot serialise the manifest: {e}"),
    })?;
    write_atomic(dir, MANIFEST_JSON, &bytes)
}

pub(super) fn read_manifest(path: &Path) -> Result<Manifest, RunError> {
    let bytes = read_capped(path, MAX_MANIFEST_BYTES)?;
    let m: Manifest = serde_json::from_slice(&bytes).map_err(|e| RunError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    if !FORMAT_VERSIONS_READ.contains(&m.format_version) {
        return Err(RunError::Inconsistent {
            path: path.to_path_buf(),
            message: format!(
                "format_version {} is not one this gyrocal reads ({FORMAT_VERSIONS_READ:?}); \
                 a newer gyrocal wrote it",
                m.format_version
            ),
        });
    }
    let h = m.plan.hash();
    if h != m.plan_hash {
        return Err(RunError::Inconsistent {
            path: path.to_path_buf(),
            message: format!(
                "plan_hash {} does not match its plan (hash {h})",
                m.plan_hash
            ),
        });
    }
    Ok(m)
}
