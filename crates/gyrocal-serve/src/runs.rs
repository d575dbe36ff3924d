//! The runs under the roots, as a viewer sees them: from each run directory's `live.json`
//! (a run going on) and `manifest.json` (how it ended, its verdict).
//!
//! Everything read here is untrusted (a run directory is anyone's file): each file is read
//! capped, parsed without panicking, and a directory is a run only when it is a real
//! directory directly under a root (a symlink is never followed, so nothing outside a root is
//! read whatever a root holds).

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use gyrocal_run::live::{LIVE_JSON, LiveState, StepSummary};
use serde::Serialize;
use serde_json::Value;

/// The most of a run directory's small JSON files read (a manifest is a few kilobytes; a
/// live state about 100 bytes a step).
const MAX_JSON_BYTES: u64 = 8 << 20;

/// The most run directories looked at under one root (bounded work per request and poll).
pub const MAX_RUNS_PER_ROOT: usize = 5000;

/// A running run whose live state is older than this is stale (its writer updates it at
/// least at every step's end and every half second while readings come).
pub const STALE_AFTER: Duration = Duration::from_secs(120);

/// A run's address: a run directory (which root, and its name directly under it), or a run
/// known through the catalog's `live_runs` (its host and its run id, `root` unused).
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct RunKey {
    /// Index of the root (in the order given).
    pub root: usize,
    /// The directory's name (the run id).
    pub name: String,
    /// The host of a run known through the catalog (`None`: a run directory under a root).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub host: Option<String>,
}

impl RunKey {
    /// The run directory `name` under root `root`.
    pub fn local(root: usize, name: String) -> RunKey {
        RunKey {
            root,
            name,
            host: None,
        }
    }

    /// The run page's path (`/run/0/NAME`, or `/live/HOST/NAME` for a run known through the
    /// catalog), the parts percent-encoded.
    pub fn href(&self) -> String {
        match &self.host {
            Some(host) => format!("/live/{}/{}", encode(host), encode(&self.name)),
            None => format!("/run/{}/{}", self.root, encode(&self.name)),
        }
    }
}

/// Percent-encodes all but unreserved characters (RFC 3986).
pub fn encode(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b'~') {
            out.push(char::from(b));
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// A run as the dashboard and the API show it.
#[derive(Debug, Clone, Serialize)]
pub struct RunView {
    /// Where it is.
    pub key: RunKey,
    /// Its page.
    pub href: String,
    /// The plan's name.
    pub plan_name: String,
    /// The plan's kind.
    pub plan_kind: String,
    /// The station's id.
    pub station: Option<String>,
    /// The gyro's serial.
    pub gyro_serial: Option<String>,
    /// `running`, `complete`, `aborted`, `failed` (the live state's, else the manifest's).
    pub status: String,
    /// A running run whose writer is gone or stopped updating.
    pub stale: bool,
    /// Why it is stale.
    pub stale_reason: Option<String>,
    /// The phase (live state), else the status.
    pub phase: String,
    /// Step under way, of `steps`.
    pub step: usize,
    /// Steps in the plan.
    pub steps: usize,
    /// Steps recorded.
    pub steps_done: usize,
    /// Estimated time to the end, s.
    pub eta_s: Option<f64>,
    /// The last reading, V.
    pub last_reading_v: Option<f64>,
    /// The running mean, V.
    pub running_mean_v: Option<f64>,
    /// The table's state.
    pub table: Option<String>,
    /// The verdict, once judged.
    pub verdict: Option<String>,
    /// Why it failed or was aborted.
    pub reason: Option<String>,
    /// Started, RFC 3339 UTC.
    pub started_utc: Option<String>,
    /// Ended, RFC 3339 UTC.
    pub ended_utc: Option<String>,
    /// The live state's or the manifest's last update, RFC 3339 UTC.
    pub updated_utc: Option<String>,
    /// The report page exists (`report.html`).
    pub has_report: bool,
}

/// A run with its steps (the run page).
#[derive(Debug, Clone, Serialize)]
pub struct RunDetail {
    /// The summary.
    #[serde(flatten)]
    pub view: RunView,
    /// Its recorded steps (the live state's, else steps.csv's).
    pub step_summaries: Vec<StepSummary>,
    /// A drift record's running Allan deviation `(τ s, σ V)` from its live state (empty
    /// otherwise; see [`LiveState::adev_v`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub adev_v: Vec<(f64, f64)>,
    /// The run directory's files (names only), for links.
    pub files: Vec<String>,
}

/// Reads a small file, at most [`MAX_JSON_BYTES`], not through a symlink.
fn read_capped(path: &Path) -> Option<Vec<u8>> {
    use std::io::Read as _;
    let meta = std::fs::symlink_metadata(path).ok()?;
    if !meta.is_file() || meta.len() > MAX_JSON_BYTES {
        return None;
    }
    let f = std::fs::File::open(path).ok()?;
    let mut buf = Vec::with_capacity(usize::try_from(meta.len()).unwrap_or(0));
    f.take(MAX_JSON_BYTES).read_to_end(&mut buf).ok()?;
    Some(buf)
}

fn read_json(path: &Path) -> Option<Value> {
    serde_json::from_slice(&read_capped(path)?).ok()
}

fn s(v: &Value, path: &[&str]) -> Option<String> {
    let mut v = v;
    for p in path {
        v = v.get(p)?;
    }
    v.as_str().map(str::to_string)
}

/// A name that may be a run directory's under a root: one path component, not `.`/`..`,
/// nothing hidden, no separator or NUL (checked after percent-decoding, which the router
/// does once: `%2e%2e` arrives here as `..` and is refused).
pub fn safe_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 255
        && !name.starts_with('.')
        && !name.contains(['/', '\\', '\0'])
}

/// The run directory `name` directly under `root`, when it is a real directory (not a
/// symlink) inside the root.
pub fn run_dir(root: &Path, name: &str) -> Option<PathBuf> {
    if !safe_name(name) {
        return None;
    }
    let dir = root.join(name);
    let meta = std::fs::symlink_metadata(&dir).ok()?;
    if !meta.is_dir() {
        return None;
    }
    // belt and braces: the canonical path must still be under the canonical root
    let (canon_root, canon) = (root.canonicalize().ok()?, dir.canonicalize().ok()?);
    canon.starts_with(&canon_root).then_some(dir)
}

/// The run directories under `root` (direct children with a manifest or a live state),
/// at most [`MAX_RUNS_PER_ROOT`].
pub fn list_dirs(root: &Path) -> Vec<(String, PathBuf)> {
    let Ok(rd) = std::fs::read_dir(root) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for entry in rd.flatten().take(MAX_RUNS_PER_ROOT * 4) {
        let Ok(ft) = entry.file_type() else { continue };
        if !ft.is_dir() {
            continue; // a symlink's file type is a symlink: never followed
        }
        let Some(name) = entry.file_name().to_str().map(str::to_string) else {
            continue;
        };
        if !safe_name(&name) {
            continue;
        }
        let dir = entry.path();
        if dir.join("manifest.json").is_file() || dir.join(LIVE_JSON).is_file() {
            out.push((name, dir));
            if out.len() >= MAX_RUNS_PER_ROOT {
                break;
            }
        }
    }
    out.sort();
    out
}

/// Whether the writer `pid` on `host` is gone: checked on this host only (`/proc/PID`).
fn writer_gone(pid: u32, host: &str) -> bool {
    host == gyrocal_files::rundir::host_name()
        && Path::new("/proc/self").exists()
        && !Path::new("/proc").join(pid.to_string()).exists()
}

fn age(utc: &str, now: SystemTime) -> Option<Duration> {
    let t = gyrocal_files::parse_rfc3339_utc(utc)?;
    now.duration_since(t).ok()
}

/// The run in `dir` (`key`), or `None` when it is not a readable run (stale after
/// [`STALE_AFTER`]).
pub fn view(key: RunKey, dir: &Path, now: SystemTime) -> Option<RunDetail> {
    view_with(key, dir, now, STALE_AFTER)
}

/// [`view`], a running run stale once its live state is older than `stale_after`.
pub fn view_with(
    key: RunKey,
    dir: &Path,
    now: SystemTime,
    stale_after: Duration,
) -> Option<RunDetail> {
    let live: Option<LiveState> =
        read_capped(&dir.join(LIVE_JSON)).and_then(|b| serde_json::from_slice(&b).ok());
    let manifest = read_json(&dir.join("manifest.json"));
    if live.is_none() && manifest.is_none() {
        return None;
    }
    let m = manifest.unwrap_or(Value::Null);
    let m_status = s(&m, &["status"]);
    let fit = read_json(&dir.join("fit.json"));
    let verdict = s(&m, &["acceptance", "verdict"])
        .or_else(|| fit.as_ref().and_then(|f| s(f, &["acceptance", "verdict"])))
        .or_else(|| live.as_ref().and_then(|l| l.verdict.clone()));
    let files = list_files(dir);
    let has_report = files.iter().any(|f| f == "report.html");
    let mut v = RunView {
        href: key.href(),
        key,
        plan_name: s(&m, &["plan", "name"]).unwrap_or_default(),
        plan_kind: s(&m, &["plan", "kind"]).unwrap_or_else(|| "scale_factor".into()),
        station: s(&m, &["station", "id"]),
        gyro_serial: s(&m, &["dut", "serial"]),
        status: m_status.clone().unwrap_or_else(|| "running".into()),
        stale: false,
        stale_reason: None,
        phase: String::new(),
        step: 0,
        steps: m
            .get("steps_total")
            .and_then(Value::as_u64)
            .and_then(|n| usize::try_from(n).ok())
            .unwrap_or(0),
        steps_done: m
            .get("steps_done")
            .and_then(Value::as_array)
            .map_or(0, Vec::len),
        eta_s: None,
        last_reading_v: None,
        running_mean_v: None,
        table: None,
        verdict,
        reason: s(&m, &["reason"]),
        started_utc: s(&m, &["started_utc"]),
        ended_utc: s(&m, &["ended_utc"]),
        updated_utc: s(&m, &["updated_utc"]),
        has_report,
    };
    let mut steps = Vec::new();
    let mut adev_v = Vec::new();
    if let Some(l) = live {
        v.plan_name = l.plan_name;
        v.plan_kind = l.plan_kind;
        v.station = l.station.or(v.station);
        v.gyro_serial = l.gyro_serial.or(v.gyro_serial);
        // the manifest's end wins over a live state cut short (a crash between the two)
        if m_status.as_deref().is_none_or(|st| st == "running") {
            v.status = l.status.clone();
        }
        v.phase = l.phase;
        v.step = l.step;
        v.steps = l.steps;
        v.steps_done = l.steps_done;
        v.eta_s = l.eta_s;
        v.last_reading_v = l.last_reading_v;
        v.running_mean_v = l.running_mean_v;
        v.table = l.table;
        v.reason = v.reason.or(l.reason);
        v.updated_utc = Some(l.updated_utc.clone());
        steps = l.step_summaries;
        adev_v = l.adev_v;
        if v.status == "running" {
            if writer_gone(l.pid, &l.hostname) {
                v.stale = true;
                v.stale_reason = Some(format!("its process ({} on {}) is gone", l.pid, l.hostname));
            } else if age(&l.updated_utc, now).is_some_and(|a| a > stale_after) {
                v.stale = true;
                v.stale_reason = Some(format!("no update since {}", l.updated_utc));
            }
        }
    } else if v.status == "running"
        && let Ok(Some(holder)) = gyrocal_files::rundir::lock_holder(dir)
        && holder.state() == gyrocal_files::rundir::HolderState::Dead
    {
        v.stale = true;
        v.stale_reason = Some(format!(
            "its process ({} on {}) is gone",
            holder.pid, holder.host
        ));
    }
    if v.phase.is_empty() {
        v.phase = match v.status.as_str() {
            "complete" => "done".into(),
            other => other.to_string(),
        };
    }
    if v.stale {
        v.phase = "stale".into();
    }
    if steps.is_empty() {
        steps = steps_csv(dir);
    }
    Some(RunDetail {
        view: v,
        step_summaries: steps,
        adev_v,
        files,
    })
}

/// The steps of a run without a live state (an older run): steps.csv's `step_no`, `rate_dps`,
/// `volts`, `volts_std`, `n`, `overloads`, `t_end_s` by header name; a malformed row is
/// left out.
fn steps_csv(dir: &Path) -> Vec<StepSummary> {
    let Some(bytes) = read_capped(&dir.join("steps.csv")) else {
        return Vec::new();
    };
    let text = String::from_utf8_lossy(&bytes);
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let Some(header) = lines.next() else {
        return Vec::new();
    };
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let at = |name: &str| cols.iter().position(|c| *c == name);
    // `step_no` counts from 1; format 2's `step` from 0
    let (i_step, base) = match (at("step_no"), at("step")) {
        (Some(i), _) => (i, 0),
        (None, Some(i)) => (i, 1),
        (None, None) => return Vec::new(),
    };
    let (Some(i_rate), Some(i_v)) = (at("rate_dps"), at("volts")) else {
        return Vec::new();
    };
    let (i_std, i_n, i_ov, i_t) = (at("volts_std"), at("n"), at("overloads"), at("t_end_s"));
    lines
        .filter_map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            let num = |i: usize| cells.get(i).and_then(|c| c.trim().parse::<f64>().ok());
            let int = |i: Option<usize>| {
                i.and_then(|i| cells.get(i))
                    .and_then(|c| c.trim().parse::<u64>().ok())
            };
            Some(StepSummary {
                number: cells.get(i_step)?.trim().parse::<usize>().ok()? + base,
                rate_dps: num(i_rate)?,
                volts: num(i_v)?,
                volts_std: i_std.and_then(num),
                n: int(i_n).unwrap_or(0),
                overloads: int(i_ov).unwrap_or(0),
                t_end_s: i_t.and_then(num).unwrap_or(f64::NAN),
            })
        })
        .collect()
}

/// The regular files directly in a run directory (names), sorted; hidden ones left out.
pub fn list_files(dir: &Path) -> Vec<String> {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut out: Vec<String> = rd
        .flatten()
        .take(1000)
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| e.file_name().to_str().map(str::to_string))
        .filter(|n| safe_name(n))
        .collect();
    out.sort();
    out
}

/// Every run under every root (stale after [`STALE_AFTER`]).
pub fn all(roots: &[PathBuf], now: SystemTime) -> Vec<RunView> {
    all_with(roots, now, STALE_AFTER)
}

/// [`all`], a running run stale once its live state is older than `stale_after`.
pub fn all_with(roots: &[PathBuf], now: SystemTime, stale_after: Duration) -> Vec<RunView> {
    let mut out = Vec::new();
    for (i, root) in roots.iter().enumerate() {
        for (name, dir) in list_dirs(root) {
            if let Some(d) = view_with(RunKey::local(i, name), &dir, now, stale_after) {
                out.push(d.view);
            }
        }
    }
    out
}

/// A run known through the catalog's `live_runs` (another bench's, see
/// [`gyrocal_catalog::LiveRow`]): its state from the row's JSON (the columns when that does
/// not read), marked stale as a local run is when it says `running` and its last update is
/// older than [`STALE_AFTER`].
pub fn from_row(row: &gyrocal_catalog::LiveRow, now: SystemTime) -> RunDetail {
    let live: Option<LiveState> = serde_json::from_str(&row.state_json).ok();
    let count = |n: i64| usize::try_from(n).unwrap_or(0);
    let key = RunKey {
        root: 0,
        name: row.run_id.clone(),
        host: Some(row.host.clone()),
    };
    let mut v = RunView {
        href: key.href(),
        key,
        plan_name: row.plan_name.clone(),
        plan_kind: row.kind.clone(),
        station: row.station_id.clone(),
        gyro_serial: row.dut_serial.clone(),
        status: row.status.clone(),
        stale: false,
        stale_reason: None,
        phase: row.phase.clone(),
        step: count(row.step),
        steps: count(row.steps),
        steps_done: count(row.steps_done),
        eta_s: row.eta_s,
        last_reading_v: row.last_reading_v,
        running_mean_v: row.running_mean_v,
        table: row.table_state.clone(),
        verdict: row.verdict.clone(),
        reason: live.as_ref().and_then(|l| l.reason.clone()),
        started_utc: live.as_ref().and_then(|l| l.started_utc.clone()),
        ended_utc: live.as_ref().and_then(|l| l.ended_utc.clone()),
        updated_utc: Some(row.updated_utc.clone()),
        has_report: false,
    };
    if v.status == "running" && age(&row.updated_utc, now).is_some_and(|a| a > STALE_AFTER) {
        v.stale = true;
        v.stale_reason = Some(format!(
            "no update since {} (from {})",
            row.updated_utc, row.host
        ));
        v.phase = "stale".into();
    }
    let (step_summaries, adev_v) =
        live.map_or_else(Default::default, |l| (l.step_summaries, l.adev_v));
    RunDetail {
        view: v,
        step_summaries,
        adev_v,
        files: Vec::new(),
    }
}

/// The runs under the roots and, after them, the runs known through the catalog that are not
/// under a root (a run in both is shown once, from its directory: the truth).
pub fn merge(
    mut local: Vec<RunView>,
    rows: &[gyrocal_catalog::LiveRow],
    now: SystemTime,
) -> Vec<RunView> {
    let names: std::collections::HashSet<String> =
        local.iter().map(|v| v.key.name.clone()).collect();
    for row in rows {
        if !names.contains(&row.run_id) {
            local.push(from_row(row, now).view);
        }
    }
    local
}
