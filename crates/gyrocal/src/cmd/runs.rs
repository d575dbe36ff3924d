//! `gyrocal runs`: the runs in the catalog, newest first, as a table or JSON.
//!
//! The columns are as wide as their widest cell (a long station name or serial shifts the
//! columns after it, never misaligns them). A run the catalog has as `running` is checked
//! against its run directory's lock (`.lock` names the host, PID and start of the process
//! that holds it): a killed process (SIGKILL, a power cut) leaves the manifest at `running`,
//! and the table then says `stale`, with a line under it naming the process that is gone.

use std::path::Path;

use clap::Args;
use gyrocal_catalog::RunFilter;
use gyrocal_files::parse_rfc3339_utc;
use gyrocal_files::rundir::{HolderState, LockHolder};

use crate::BadInput;
use crate::cmd::catalog::{CatalogOpt, open, user_error};

/// Arguments of `gyrocal runs`.
#[derive(Debug, Args)]
pub struct RunsArgs {
    /// Only the runs of this gyro (serial number).
    #[arg(long, value_name = "SERIAL")]
    pub serial: Option<String>,
    /// Only runs in this state: running, complete, aborted, failed.
    #[arg(long, value_name = "STATUS")]
    pub status: Option<String>,
    /// Only runs started on or after this date (YYYY-MM-DD, UTC) or time (RFC 3339 UTC).
    #[arg(long, value_name = "DATE")]
    pub since: Option<String>,
    /// Only runs of this station.
    #[arg(long, value_name = "ID")]
    pub station: Option<String>,
    /// At most this many runs.
    #[arg(long, value_name = "N")]
    pub limit: Option<i64>,
    /// Print JSON (one array of runs with their results).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    catalog: CatalogOpt,
}

/// `YYYY-MM-DD` or an RFC 3339 UTC time, else an error.
fn check_since(since: &str) -> Result<(), BadInput> {
    let b = since.as_bytes();
    let date_ok = b.len() >= 10
        && b[..10].iter().enumerate().all(|(i, c)| {
            if i == 4 || i == 7 {
                *c == b'-'
            } else {
                c.is_ascii_digit()
            }
        });
    if date_ok && (b.len() == 10 || b.get(10) == Some(&b'T')) {
        Ok(())
    } else {
        Err(BadInput(format!(
            "--since {since}: expected a date YYYY-MM-DD or a time YYYY-MM-DDTHH:MM:SSZ (UTC)"
        )))
    }
}

/// Runs `gyrocal runs`.
pub fn run(args: &RunsArgs) -> anyhow::Result<u8> {
    if let Some(s) = &args.since {
        check_since(s)?;
    }
    if let Some(s) = &args.status
        && !["running", "complete", "aborted", "failed"].contains(&s.as_str())
    {
        return Err(BadInput(format!(
            "--status {s}: expected running, complete, aborted or failed"
        ))
        .into());
    }
    let (rt, catalog) = open(&args.catalog)?;
    let filter = RunFilter {
        serial: args.serial.clone(),
        status: args.status.clone(),
        since: args.since.clone(),
        station: args.station.clone(),
        limit: args.limit,
    };
    let runs = rt.block_on(catalog.runs(&filter)).map_err(user_error)?;
    rt.block_on(catalog.close());
    // a run the catalog has as running: is its process still there? (its run directory's lock)
    let locks: Vec<Option<LockView>> = runs
        .iter()
        .map(|r| (r.run.status == "running").then(|| LockView::of(Path::new(&r.run.directory))))
        .collect();
    if args.json {
        let mut doc = serde_json::to_value(&runs)?;
        if let Some(items) = doc.as_array_mut() {
            for ((item, lock), r) in items.iter_mut().zip(&locks).zip(&runs) {
                if let (Some(lock), Some(obj)) = (lock, item.as_object_mut()) {
                    obj.insert("lock".into(), lock.json(&r.run.directory));
                }
            }
        }
        println!("{}", serde_json::to_string_pretty(&doc)?);
        return Ok(0);
    }
    if runs.is_empty() {
        println!("no runs in {}", catalog.url());
        return Ok(0);
    }
    let header = [
        "STARTED (UTC)",
        "SERIAL",
        "STATUS",
        "VERDICT",
        "K V/(°/s)",
        "STATION",
        "SIM",
        "DIRECTORY",
    ];
    let rows: Vec<[String; 8]> = runs
        .iter()
        .zip(&locks)
        .map(|(r, lock)| {
            let k = r
                .results
                .as_ref()
                .and_then(|x| x.scale_factor)
                .map_or("—".to_string(), |k| format!("{k:.7}"));
            [
                r.run.started_utc.chars().take(19).collect::<String>(),
                r.run.dut_serial.clone().unwrap_or_else(|| "—".into()),
                lock.as_ref()
                    .map_or_else(|| r.run.status.clone(), |l| l.status().to_string()),
                r.run.verdict.clone().unwrap_or_else(|| "—".into()),
                k,
                r.run.station_id.clone().unwrap_or_else(|| "—".into()),
                if r.run.simulated { "yes" } else { "" }.to_string(),
                r.run.directory.clone(),
            ]
        })
        .collect();
    for line in table(&header, &rows) {
        println!("{line}");
    }
    // the runs that say running: what their lock says, one line each
    let now = std::time::SystemTime::now();
    for (r, lock) in runs.iter().zip(&locks) {
        if let Some(lock) = lock {
            println!("{}: {}", r.run.directory, lock.words(now, &r.run.directory));
        }
    }
    Ok(0)
}

/// Columns as wide as their widest cell (counted in characters: `—` and `°` are one column
/// each), two spaces apart; the K column right-aligned, the last column not padded.
fn table<const N: usize>(header: &[&str; N], rows: &[[String; N]]) -> Vec<String> {
    let width = |i: usize| {
        rows.iter()
            .map(|r| r[i].chars().count())
            .chain([header[i].chars().count()])
            .max()
            .unwrap_or(0)
    };
    let widths: Vec<usize> = (0..N).map(width).collect();
    let line = |cells: [&str; N]| {
        let mut out = String::new();
        for (i, cell) in cells.iter().enumerate() {
            if i + 1 == N {
                out.push_str(cell);
            } else if i == 4 {
                out.push_str(&format!("{cell:>w$}  ", w = widths[i]));
            } else {
                out.push_str(&format!("{cell:<w$}  ", w = widths[i]));
            }
        }
        out.trim_end().to_string()
    };
    let mut out = vec![line(*header)];
    for r in rows {
        out.push(line(std::array::from_fn(|i| r[i].as_str())));
    }
    out
}

/// What the lock of a run the catalog has as `running` says: its holder, and whether that
/// process is still alive on this host.
#[derive(Debug)]
enum LockView {
    /// The holder's host, PID, since when, and whether it is alive.
    Held(LockHolder, HolderState),
    /// No `.lock` in the run directory (or the directory is gone): no process holds it.
    NoLock,
    /// A `.lock` without a holder's name (left by an earlier gyrocal): nothing to check.
    Anonymous,
    /// The lock could not be read.
    Unreadable(String),
}

impl LockView {
    fn of(dir: &Path) -> LockView {
        if !dir.join(gyrocal_files::rundir::MANIFEST_JSON).exists() {
            return LockView::NoLock;
        }
        match gyrocal_files::rundir::lock_holder(dir) {
            Ok(Some(h)) => {
                let state = h.state();
                LockView::Held(h, state)
            }
            Ok(None) if dir.join(gyrocal_files::rundir::LOCK_FILE).exists() => LockView::Anonymous,
            Ok(None) => LockView::NoLock,
            Err(e) => LockView::Unreadable(e.to_string()),
        }
    }

    /// The STATUS column: `running`, `stale` (its process is gone), or `running?` (cannot
    /// tell).
    fn status(&self) -> &'static str {
        match self {
            LockView::Held(_, HolderState::Alive) => "running",
            LockView::Held(_, HolderState::Dead) | LockView::NoLock => "stale",
            _ => "running?",
        }
    }

    /// The line under the table.
    fn words(&self, now: std::time::SystemTime, dir: &str) -> String {
        match self {
            LockView::Held(h, state) => {
                let ago = parse_rfc3339_utc(&h.since_utc)
                    .and_then(|t| now.duration_since(t).ok())
                    .map_or(String::new(), |d| format!(", {} ago", age(d)));
                let since = format!("since {}{ago}", h.since_utc);
                match state {
                    HolderState::Alive => {
                        format!("running (host {}, pid {}, {since})", h.host, h.pid)
                    }
                    HolderState::Dead => format!(
                        "stale (process {} not alive on this host; lock taken {since}): the run was killed; `gyrocal run --resume {dir}` continues it",
                        h.pid
                    ),
                    HolderState::Unknown => format!(
                        "running? (host {}, pid {}, {since}: another host, not checked from here)",
                        h.host, h.pid
                    ),
                }
            }
            LockView::NoLock => format!(
                "stale (no lock in the run directory: its process ended without closing the run); `gyrocal run --resume {dir}` continues it"
            ),
            LockView::Anonymous => {
                "running? (its lock names no process: written by an earlier gyrocal)".into()
            }
            LockView::Unreadable(e) => format!("running? (its lock cannot be read: {e})"),
        }
    }

    fn json(&self, dir: &str) -> serde_json::Value {
        let (holder, alive) = match self {
            LockView::Held(h, s) => (
                serde_json::json!(h),
                match s {
                    HolderState::Alive => serde_json::json!(true),
                    HolderState::Dead => serde_json::json!(false),
                    HolderState::Unknown => serde_json::Value::Null,
                },
            ),
            LockView::NoLock => (serde_json::Value::Null, serde_json::json!(false)),
            _ => (serde_json::Value::Null, serde_json::Value::Null),
        };
        serde_json::json!({
            "state": self.status(),
            "holder": holder,
            "alive": alive,
            "text": self.words(std::time::SystemTime::now(), dir),
        })
    }
}

/// `3 d 4 h`, `2 h 5 min`, `7 min`, `12 s`.
fn age(d: std::time::Duration) -> String {
    let s = d.as_secs();
    match s {
        0..60 => format!("{s} s"),
        60..3600 => format!("{} min", s / 60),
        3600..86400 => format!("{} h {} min", s / 3600, (s / 60) % 60),
        _ => format!("{} d {} h", s / 86400, (s / 3600) % 24),
    }
}
