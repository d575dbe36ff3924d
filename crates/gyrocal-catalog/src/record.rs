//! A run directory read into the rows the catalog holds ([`RunRecord`]).
//!
//! The typed reader of `gyrocal-files` ([`gyrocal_files::load`]) gives the manifest and the
//! steps; `manifest.json` is read a second time as plain JSON for the parts that not every
//! gyrocal writes (the station, the acceptance verdict): absent parts become NULL columns.
//! The run's figures are the analysis crate's to read, typed, from its results file by the
//! run's kind ([`gyrocal_analysis::figures`]: `fit.json` or `allan.json`, every figure
//! optional).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::error::CatalogError;

/// The `kind` of every run gyrocal writes today.
pub const KIND_SCALE_FACTOR: &str = "scale_factor";

/// One row of `runs`: who, what, when, where, and how it ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRow {
    /// The run's id: the manifest's `run_id` (or `id`) when it has one, else
    /// `sha256(absolute directory + "\n" + started_utc)` in hex, first 32 digits.
    pub id: String,
    /// The run directory, absolute, as imported.
    pub directory: String,
    /// The host that imported it.
    pub host: Option<String>,
    /// The station's id (manifest `station.id`).
    pub station_id: Option<String>,
    /// The plan's name.
    pub plan_name: String,
    /// The plan's SHA-256.
    pub plan_hash: String,
    /// What the run measured: the plan's kind ([`KIND_SCALE_FACTOR`] or `drift`).
    pub kind: String,
    /// The gyro's serial number.
    pub dut_serial: Option<String>,
    /// The gyro's model.
    pub dut_model: Option<String>,
    /// The operator.
    pub operator: Option<String>,
    /// The customer.
    pub customer: Option<String>,
    /// `running`, `complete`, `aborted` or `failed`.
    pub status: String,
    /// Why it failed or was aborted.
    pub reason: Option<String>,
    /// Wall-clock start, RFC 3339 UTC.
    pub started_utc: String,
    /// Wall-clock end, RFC 3339 UTC.
    pub ended_utc: Option<String>,
    /// Whether the bench was simulated.
    pub simulated: bool,
    /// The acceptance verdict (`pass`, `marginal`, `indeterminate`, `fail`) when judged.
    pub verdict: Option<String>,
    /// The acceptance decision rule (`simple`, `guarded`) when judged.
    pub acceptance_rule: Option<String>,
    /// Steps in the schedule.
    pub steps_total: i64,
    /// Steps finished.
    pub steps_done: i64,
    /// Ambient temperature, °C, as entered.
    pub ambient_c: Option<f64>,
    /// Relative humidity, %, as entered.
    pub humidity_pct: Option<f64>,
    /// The gyrocal version that wrote the run.
    pub gyrocal_version: Option<String>,
}

/// One row of `results`: the run's headline figures (the analysis crate's
/// [`gyrocal_analysis::Figures`]: a sweep's fit or a drift record's noise terms, expanded
/// uncertainties at k = 2).
pub use gyrocal_analysis::Figures as Results;

/// One row of `steps`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepRow {
    /// 0-based index in the schedule.
    pub step: i64,
    /// 0-based pass.
    pub pass: i64,
    /// Demanded rate, °/s.
    pub rate_dps: f64,
    /// Mean measured rate, °/s.
    pub rate_meas_dps: Option<f64>,
    /// Mean output, V.
    pub volts: f64,
    /// Standard deviation of the readings, V.
    pub volts_std: Option<f64>,
    /// Readings averaged.
    pub n: i64,
    /// Overloaded readings.
    pub overloads: i64,
}

/// One row of `instruments`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct InstrumentRow {
    /// `multimeter` or `table`.
    pub role: String,
    /// The instrument's identity reply (`*IDN?`).
    pub identity: Option<String>,
    /// Model.
    pub model: Option<String>,
    /// The lab's asset id.
    pub asset_id: Option<String>,
    /// Serial number.
    pub serial: Option<String>,
    /// Calibration certificate number.
    pub certificate: Option<String>,
    /// Date of its calibration.
    pub calibrated: Option<String>,
    /// Date its calibration is due.
    pub due: Option<String>,
}

/// One row of `checks`: a quantity judged against its limits.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CheckRow {
    /// The quantity (`scale_factor`, `bias_dph`, ...).
    pub quantity: String,
    /// Its value.
    pub value: Option<f64>,
    /// Its unit.
    pub unit: Option<String>,
    /// Its expanded uncertainty.
    pub expanded_uncertainty: Option<f64>,
    /// Lower limit.
    pub min: Option<f64>,
    /// Upper limit.
    pub max: Option<f64>,
    /// Lower limit of the non-marginal band.
    pub marginal_min: Option<f64>,
    /// Upper limit of the non-marginal band.
    pub marginal_max: Option<f64>,
    /// `pass`, `marginal`, `indeterminate` or `fail`.
    pub verdict: Option<String>,
}

/// Everything the catalog holds about one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// The `runs` row.
    pub run: RunRow,
    /// The `results` row, when the run was fitted.
    pub results: Option<Results>,
    /// The finished steps.
    pub steps: Vec<StepRow>,
    /// The instruments.
    pub instruments: Vec<InstrumentRow>,
    /// The acceptance checks.
    pub checks: Vec<CheckRow>,
    /// A temperature series' figures (the `catalog` member of its `series.json`); `None` for
    /// every other run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub series: Option<crate::series::SeriesRecord>,
}

/// This machine's host name (`/proc/sys/kernel/hostname`, `/etc/hostname`, `$HOSTNAME`).
pub fn host_name() -> Option<String> {
    ["/proc/sys/kernel/hostname", "/etc/hostname"]
        .iter()
        .find_map(|p| std::fs::read_to_string(p).ok())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
}

/// True when `dir` looks like a run directory (it holds `manifest.json` and `steps.csv`).
pub fn is_run_dir(dir: &Path) -> bool {
    dir.join(gyrocal_files::rundir::MANIFEST_JSON).is_file()
        && dir.join(gyrocal_files::rundir::STEPS_CSV).is_file()
}

fn not_a_run(dir: &Path, message: impl Into<String>) -> CatalogError {
    CatalogError::NotARun {
        path: dir.to_path_buf(),
        message: message.into(),
    }
}

fn read_json(dir: &Path, name: &str) -> Result<Option<Value>, CatalogError> {
    let path = dir.join(name);
    if !path.exists() {
        return Ok(None);
    }
    let bytes = gyrocal_files::rundir::read_capped(&path, gyrocal_files::rundir::MAX_FIT_BYTES)
        .map_err(|e| not_a_run(dir, e.to_string()))?;
    serde_json::from_slice(&bytes)
        .map(Some)
        .map_err(|e| not_a_run(dir, format!("{name}: {e}")))
}

fn absolute(dir: &Path) -> PathBuf {
    std::fs::canonicalize(dir).unwrap_or_else(|_| {
        std::env::current_dir()
            .map(|c| c.join(dir))
            .unwrap_or_else(|_| dir.to_path_buf())
    })
}

fn s(v: &Value, key: &str) -> Option<String> {
    match v.get(key)? {
        Value::String(s) if !s.is_empty() => Some(s.clone()),
        Value::Number(n) => Some(n.to_string()),
        _ => None,
    }
}

fn f(v: &Value, key: &str) -> Option<f64> {
    v.get(key)?.as_f64().filter(|x| x.is_finite())
}

/// Reads a run directory into a [`RunRecord`] (synchronous file reads: a few kilobytes of
/// manifest and steps, and fit.json). `host` is recorded as the importing host.
pub fn read_run(dir: &Path, host: Option<&str>) -> Result<RunRecord, CatalogError> {
    if !dir.join(gyrocal_files::rundir::MANIFEST_JSON).is_file() {
        return Err(not_a_run(dir, "it has no manifest.json"));
    }
    let data = gyrocal_files::load(dir).map_err(|e| not_a_run(dir, e.to_string()))?;
    let raw = read_json(dir, gyrocal_files::rundir::MANIFEST_JSON)?.unwrap_or(Value::Null);
    let fit = match read_json(dir, gyrocal_files::rundir::FIT_JSON)? {
        Some(v) => Some(v),
        // format 1 embedded the fit in the manifest
        None => raw.get("fit").filter(|v| v.is_object()).cloned(),
    };
    let m = &data.manifest;
    let directory = absolute(dir);
    let directory_text = directory.display().to_string();
    let id = s(&raw, "run_id")
        .or_else(|| s(&raw, "id"))
        .unwrap_or_else(|| {
            let h = gyrocal_files::rundir::sha256_hex(
                format!("{directory_text}\n{}", m.started_utc).as_bytes(),
            );
            h.chars().take(32).collect()
        });
    let station = raw.get("station").cloned().unwrap_or(Value::Null);
    let acceptance = raw
        .get("acceptance")
        .filter(|v| v.is_object())
        .or_else(|| fit.as_ref().and_then(|f| f.get("acceptance")))
        .cloned()
        .unwrap_or(Value::Null);
    let status = serde_json::to_value(m.status)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_else(|| format!("{:?}", m.status).to_lowercase());
    let run = RunRow {
        id,
        directory: directory_text,
        host: host.map(str::to_string),
        station_id: s(&station, "id"),
        plan_name: m.plan.name().to_string(),
        plan_hash: m.plan_hash.clone(),
        kind: m.plan.kind().as_str().to_string(),
        dut_serial: m.dut.as_ref().and_then(|d| d.serial.clone()),
        dut_model: m.dut.as_ref().and_then(|d| d.model.clone()),
        operator: m.context.as_ref().and_then(|c| c.operator.clone()),
        customer: m.context.as_ref().and_then(|c| c.customer.clone()),
        status,
        reason: m.reason.clone(),
        started_utc: m.started_utc.clone(),
        ended_utc: m.ended_utc.clone(),
        simulated: m.simulated,
        verdict: s(&acceptance, "verdict"),
        acceptance_rule: s(&acceptance, "rule"),
        steps_total: i64::try_from(m.steps_total).unwrap_or(i64::MAX),
        steps_done: i64::try_from(m.steps_done.len()).unwrap_or(i64::MAX),
        ambient_c: m.context.as_ref().and_then(|c| c.ambient_c),
        humidity_pct: m.context.as_ref().and_then(|c| c.humidity_pct),
        gyrocal_version: Some(m.gyrocal_version.clone()).filter(|v| !v.is_empty()),
    };
    // the analysis crate reads the figures of the run's kind (fit.json, allan.json) typed
    let results = gyrocal_analysis::figures(dir, m, fit.as_ref())
        .map_err(|e| not_a_run(dir, e.to_string()))?;
    let steps = data
        .steps
        .iter()
        .map(|st| StepRow {
            step: i64::try_from(st.step).unwrap_or(i64::MAX),
            pass: i64::from(st.pass),
            rate_dps: st.rate_dps,
            rate_meas_dps: st.rate_meas_dps,
            volts: st.volts,
            volts_std: st.volts_std,
            n: i64::try_from(st.n).unwrap_or(i64::MAX),
            overloads: i64::try_from(st.overloads).unwrap_or(i64::MAX),
        })
        .collect();
    let instruments = instruments_of(&m.instruments, &station);
    // a series.json is read whatever the kind: only a temperature series writes one
    let series = crate::series::read_series(dir)?;
    let checks = acceptance
        .get("checks")
        .and_then(Value::as_array)
        .map(|checks| {
            checks
                .iter()
                .filter_map(|c| {
                    Some(CheckRow {
                        quantity: s(c, "quantity")?,
                        value: f(c, "value"),
                        unit: s(c, "unit"),
                        expanded_uncertainty: f(c, "expanded_uncertainty"),
                        min: f(c, "min"),
                        max: f(c, "max"),
                        marginal_min: f(c, "marginal_min"),
                        marginal_max: f(c, "marginal_max"),
                        verdict: s(c, "verdict"),
                    })
                })
                .collect()
        })
        .unwrap_or_default();
    Ok(RunRecord {
        run,
        results,
        steps,
        instruments,
        checks,
        series,
    })
}

/// Model and serial from an identity reply `MAKER,MODEL,SERIAL,FIRMWARE`.
fn idn_parts(idn: &str) -> (Option<String>, Option<String>) {
    let mut parts = idn.split(',').map(str::trim);
    let _maker = parts.next();
    let model = parts.next().filter(|s| !s.is_empty()).map(str::to_string);
    let serial = parts
        .next()
        .filter(|s| !s.is_empty() && *s != "0")
        .map(str::to_string);
    (model, serial)
}

fn instruments_of(ids: &gyrocal_files::Instruments, station: &Value) -> Vec<InstrumentRow> {
    let mut out = Vec::new();
    for (role, identity, key) in [
        ("multimeter", ids.dmm.as_deref(), "multimeter"),
        ("table", ids.table.as_deref(), "table"),
    ] {
        let st = station.get(key).filter(|v| v.is_object());
        if identity.is_none() && st.is_none() {
            continue;
        }
        let (model, serial) = identity.map(idn_parts).unwrap_or((None, None));
        let st = st.cloned().unwrap_or(Value::Null);
        out.push(InstrumentRow {
            role: role.to_string(),
            identity: identity.map(str::to_string),
            model: s(&st, "model").or(model),
            asset_id: s(&st, "asset_id"),
            serial: s(&st, "serial").or(serial),
            certificate: s(&st, "certificate"),
            calibrated: s(&st, "calibrated"),
            due: s(&st, "due"),
        });
    }
    out
}

/// The run directories under `root` (itself included), sorted; hidden directories are not
/// entered, nor is a run directory (runs do not nest). Unreadable directories are skipped
/// with a warning.
pub fn find_run_dirs(root: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        if dir.join(gyrocal_files::rundir::MANIFEST_JSON).is_file() {
            out.push(dir);
            continue;
        }
        let entries = match std::fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) => {
                tracing::warn!(dir = %dir.display(), error = %e, "cannot read the directory; skipped");
                continue;
            }
        };
        for entry in entries.flatten() {
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            if !hidden && entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(entry.path());
            }
        }
    }
    out.sort();
    out
}
