//! A run directory read into the rows the catalog holds ([`RunRecord`]).
//!
//! The typed reader of `gyrocal-files` ([`gyrocal_files::load`]) gives the manifest and the
//! steps; `manifest.json` and `fit.json` are read a second time as plain JSON for the parts
//! that not every gyrocal writes (the station, the acceptance verdict, the uncertainty budget,
//! the common-K2 asymmetry): absent parts become NULL columns. A drift record's `allan.json`
//! is read typed by the analysis crate ([`gyrocal_analysis::drift::DriftFigures`], every
//! figure optional), which also decides which of the two a run has
//! ([`gyrocal_analysis::RunKind`]).

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

/// One row of `results`: the fit's figures and their expanded uncertainties (k = 2).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Results {
    /// Scale factor K, V/(°/s).
    pub scale_factor: Option<f64>,
    /// Standard error of K from the fit, V/(°/s).
    pub scale_factor_std_error: Option<f64>,
    /// Bias K0, V.
    pub bias_v: Option<f64>,
    /// Standard error of K0, V.
    pub bias_v_std_error: Option<f64>,
    /// Bias as a rate, °/h.
    pub bias_dph: Option<f64>,
    /// Scale factor of the positive direction K+, V/(°/s).
    pub k_pos: Option<f64>,
    /// Scale factor of the negative direction K−, V/(°/s).
    pub k_neg: Option<f64>,
    /// Second-order coefficient K2, V/(°/s)² (common-K2 model when present, else the
    /// quadratic least-squares fit).
    pub k2: Option<f64>,
    /// Nonlinearity, ppm.
    pub nonlinearity_ppm: Option<f64>,
    /// Asymmetry (GJB, split lines), ppm.
    pub asymmetry_ppm: Option<f64>,
    /// Asymmetry with a common K2, ppm.
    pub asymmetry_common_k2_ppm: Option<f64>,
    /// Repeatability of K over the passes, ppm.
    pub repeatability_ppm: Option<f64>,
    /// Expanded uncertainty of K, V/(°/s).
    pub u_scale_factor: Option<f64>,
    /// Expanded uncertainty of K0, V.
    pub u_bias_v: Option<f64>,
    /// Expanded uncertainty of the bias, °/h.
    pub u_bias_dph: Option<f64>,
    /// Expanded uncertainty of K+, V/(°/s).
    pub u_k_pos: Option<f64>,
    /// Expanded uncertainty of K−, V/(°/s).
    pub u_k_neg: Option<f64>,
    /// The model the fit chose.
    pub best_model: Option<String>,
    /// A drift test's angle random walk N, °/√h (five-term fit).
    #[serde(default)]
    pub arw_deg_rt_h: Option<f64>,
    /// Expanded uncertainty (k = 2) of N, °/√h.
    #[serde(default)]
    pub u_arw_deg_rt_h: Option<f64>,
    /// A drift test's bias instability B, °/h (five-term fit).
    #[serde(default)]
    pub bias_instability_dph: Option<f64>,
    /// Expanded uncertainty (k = 2) of B, °/h.
    #[serde(default)]
    pub u_bias_instability_dph: Option<f64>,
    /// A drift test's rate random walk K, °/h/√h (five-term fit).
    #[serde(default)]
    pub rrw_dph_rt_h: Option<f64>,
    /// Expanded uncertainty (k = 2) of K, °/h/√h.
    #[serde(default)]
    pub u_rrw_dph_rt_h: Option<f64>,
    /// A drift test's bias, °/h (the Earth rate removed when the run's axis and latitude were
    /// known).
    #[serde(default)]
    pub drift_bias_dph: Option<f64>,
    /// Expanded uncertainty (k = 2) of the drift bias, °/h.
    #[serde(default)]
    pub u_drift_bias_dph: Option<f64>,
    /// GJB bias stability over 100 s windows, °/h.
    #[serde(default)]
    pub bias_stability_100s_dph: Option<f64>,
    /// The analysed record's length, s (after gaps and warm-up).
    #[serde(default)]
    pub drift_duration_s: Option<f64>,
}

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
    // the analysis crate's one dispatch on the kind: a drift record is not fitted, its figures
    // are the Allan analysis's
    let results = match gyrocal_analysis::RunKind::of(m) {
        gyrocal_analysis::RunKind::Drift => gyrocal_analysis::drift::DriftFigures::load(dir)
            .map_err(|e| not_a_run(dir, e.to_string()))?
            .map(|a| drift_results_of(&a)),
        gyrocal_analysis::RunKind::Sweep => fit.as_ref().map(|fit| results_of(fit, m)),
    };
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
    })
}

/// A drift test's figures from its `allan.json`, read typed by the analysis crate
/// ([`gyrocal_analysis::drift::DriftFigures`]): the five-term fit's N, B and K (the tests
/// recover them within their intervals where the slope reads are biased), the bias (the Earth
/// rate removed when known) and the 100 s bias stability; uncertainties expanded to k = 2. In
/// °/h only: a record left in volts has none.
fn drift_results_of(a: &gyrocal_analysis::drift::DriftFigures) -> Results {
    let k2 = |u: Option<f64>| u.map(|u| 2.0 * u);
    Results {
        arw_deg_rt_h: a.arw.value,
        u_arw_deg_rt_h: k2(a.arw.uncertainty),
        bias_instability_dph: a.bias_instability.value,
        u_bias_instability_dph: k2(a.bias_instability.uncertainty),
        rrw_dph_rt_h: a.rrw.value,
        u_rrw_dph_rt_h: k2(a.rrw.uncertainty),
        drift_bias_dph: a.bias.value,
        u_drift_bias_dph: k2(a.bias.uncertainty),
        bias_stability_100s_dph: a.bias_stability_100s,
        drift_duration_s: a.duration_s,
        ..Results::default()
    }
}

fn results_of(fit: &Value, m: &gyrocal_files::Manifest) -> Results {
    let metrics = fit.get("metrics").cloned().unwrap_or(Value::Null);
    let lsq = |model: &str| -> Option<&Value> {
        fit.get("fits")?.as_array()?.iter().find(|f| {
            f.get("method").and_then(Value::as_str) == Some("least-squares")
                && f.get("model").and_then(Value::as_str) == Some(model)
        })
    };
    let linear = lsq("linear");
    let common = metrics
        .get("asymmetry_common_k2")
        .cloned()
        .unwrap_or(Value::Null);
    let u = |q: &str| -> Option<f64> {
        fit.get("uncertainty")?
            .get("quantities")?
            .as_array()?
            .iter()
            .find(|x| x.get("quantity").and_then(Value::as_str) == Some(q))
            .and_then(|x| f(x, "expanded_uncertainty"))
    };
    let summary = m.fit_summary.as_ref();
    Results {
        scale_factor: f(&metrics, "scale_factor").or(summary.map(|s| s.scale_factor)),
        scale_factor_std_error: summary
            .and_then(|s| s.scale_factor_std_error)
            .or_else(|| linear.and_then(|l| f(l.get("std_errors")?, "k1"))),
        bias_v: f(&metrics, "bias_volts").or(summary.map(|s| s.bias_volts)),
        bias_v_std_error: summary
            .and_then(|s| s.bias_std_error)
            .or_else(|| linear.and_then(|l| f(l.get("std_errors")?, "k0"))),
        bias_dph: f(&metrics, "bias_dph"),
        k_pos: f(&metrics, "scale_factor_positive"),
        k_neg: f(&metrics, "scale_factor_negative"),
        k2: f(&common, "k2")
            .or_else(|| lsq("quadratic").and_then(|q| f(q.get("coefficients")?, "k2"))),
        nonlinearity_ppm: f(&metrics, "nonlinearity_ppm"),
        asymmetry_ppm: f(&metrics, "asymmetry_ppm"),
        asymmetry_common_k2_ppm: f(&common, "asymmetry_ppm"),
        repeatability_ppm: f(&metrics, "repeatability_ppm"),
        u_scale_factor: u("scale_factor"),
        u_bias_v: u("bias_v"),
        u_bias_dph: u("bias_dph"),
        u_k_pos: u("k_pos"),
        u_k_neg: u("k_neg"),
        best_model: s(fit, "best_model"),
        ..Results::default()
    }
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
