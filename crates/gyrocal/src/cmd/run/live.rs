//! The run's live state beyond its own `live.json`: published to a PostgreSQL catalog (the
//! lab's message bus, [`gyrocal_catalog::LiveBus`]: `live_runs` and `NOTIFY gyrocal_live`),
//! concluded with the verdict once the analysis after the run knows it, and shown by a web
//! view: `--serve [ADDR]` starts one in this process over the run's own root (reading files
//! only, on a thread and a runtime of its own, so the run's clock and its instruments never
//! wait on it), and the station's `serve` key names the lab's view, whose address for this
//! run is printed (nothing is started for it).
//!
//! None of it can stop, slow or fail the run: the bus only swaps the newest state into a
//! one-slot mailbox; a server that cannot start is a warning.

use super::*;

use std::net::SocketAddr;
use std::sync::Mutex;

use gyrocal_catalog::{CatalogUrl, LiveBus, LiveRow, MAX_STATE_JSON};
use gyrocal_run::live::{LiveFile, LiveHandle, LiveHeader, LiveState};

/// The catalog's bus of this process's run (one run per process, so one slot).
static BUS: Mutex<Option<Arc<LiveBus>>> = Mutex::new(None);
/// The live state's handle, for the verdict at the end.
static HANDLE: Mutex<Option<LiveHandle>> = Mutex::new(None);

/// How long the end of a run gives the bus for the last state (the run is over: real time).
pub(super) const LIVE_CLOSE_TIMEOUT: Duration = Duration::from_secs(3);

/// The default address of `--serve` without one: loopback, any free port.
pub(super) const SERVE_DEFAULT: &str = "127.0.0.1:0";

/// Starts the bus when the run's catalog is PostgreSQL (an SQLite file notifies no one: the
/// `live_runs` table of an SQLite catalog stays empty).
pub(super) fn start_bus(url: &CatalogUrl) {
    if matches!(url, CatalogUrl::Postgres(_))
        && let Ok(mut slot) = BUS.lock()
    {
        *slot = Some(Arc::new(LiveBus::spawn(url.clone())));
    }
}

/// The live state's sink of the run in `run`, publishing to the bus when there is one.
pub(super) fn live_sink(run: &RunDir) -> LiveFile {
    let mut live = LiveFile::new(run.path(), LiveHeader::of(run));
    if let Some(bus) = BUS.lock().ok().and_then(|b| b.clone()) {
        live = live.with_publisher(Arc::new(move |s: &LiveState| bus.publish(row_of(s))));
    }
    if let Ok(mut slot) = HANDLE.lock() {
        *slot = Some(live.handle());
    }
    live
}

/// The end of the run, after its analysis: the verdict into the last live state (file and
/// bus), then the bus given [`LIVE_CLOSE_TIMEOUT`] for it.
pub(super) fn conclude(verdict: Option<&str>) {
    if let Some(h) = HANDLE.lock().ok().and_then(|mut h| h.take()) {
        h.conclude(verdict);
    }
    if let Some(bus) = BUS.lock().ok().and_then(|mut b| b.take())
        && !bus.close(LIVE_CLOSE_TIMEOUT)
    {
        tracing::warn!(
            "the catalog did not take the run's last live state; viewers of the catalog may show it as stale (its run directory is complete)"
        );
    }
}

/// The row of `live_runs` for `state`: its JSON capped at [`MAX_STATE_JSON`] (the oldest
/// step summaries left out first; the table's columns keep the counts).
pub(super) fn row_of(state: &LiveState) -> LiveRow {
    let mut json = serde_json::to_string(state).unwrap_or_default();
    if json.len() > MAX_STATE_JSON {
        let mut s = state.clone();
        while json.len() > MAX_STATE_JSON && !s.step_summaries.is_empty() {
            let cut = s.step_summaries.len().div_ceil(2);
            s.step_summaries.drain(..cut);
            json = serde_json::to_string(&s).unwrap_or_default();
        }
        if json.len() > MAX_STATE_JSON {
            json = "{}".into();
        }
    }
    let int = |n: usize| i64::try_from(n).unwrap_or(i64::MAX);
    LiveRow {
        run_id: state.run_id.clone(),
        host: state.hostname.clone(),
        station_id: state.station.clone(),
        dut_serial: state.gyro_serial.clone(),
        plan_name: state.plan_name.clone(),
        kind: state.plan_kind.clone(),
        phase: state.phase.clone(),
        step: int(state.step),
        steps: int(state.steps),
        steps_done: int(state.steps_done),
        eta_s: state.eta_s.filter(|x| x.is_finite()),
        last_reading_v: state.last_reading_v.filter(|x| x.is_finite()),
        running_mean_v: state.running_mean_v.filter(|x| x.is_finite()),
        table_state: state.table.clone(),
        status: state.status.clone(),
        verdict: state.verdict.clone(),
        updated_utc: state.updated_utc.clone(),
        state_json: json,
    }
}

/// `--serve ADDR`: the address, refused off loopback without `$GYROCAL_SERVE_TOKEN`.
pub(super) fn serve_addr(text: &str) -> anyhow::Result<(SocketAddr, Option<String>)> {
    let addr: SocketAddr = text.trim().parse().map_err(|e| {
        BadInput(format!(
            "--serve {text}: {e}: write an address and port such as 127.0.0.1:8737 (0: any free port)"
        ))
    })?;
    let token = std::env::var(crate::cmd::serve::TOKEN_ENV)
        .ok()
        .filter(|t| !t.is_empty());
    gyrocal_serve::check_bind(&addr, token.as_deref())
        .map_err(|e| BadInput(format!("--serve: {e}")))?;
    Ok((addr, token))
}

/// Starts the web view over `root` on a thread of its own (its own runtime, in real time)
/// and returns the address it listens on.
fn start_server(
    addr: SocketAddr,
    token: Option<String>,
    root: PathBuf,
) -> anyhow::Result<SocketAddr> {
    let listener = std::net::TcpListener::bind(addr)
        .with_context(|| format!("--serve: cannot listen on {addr}"))?;
    listener.set_nonblocking(true)?;
    let local = listener.local_addr()?;
    let cfg = gyrocal_serve::ServeConfig {
        roots: vec![root],
        token,
        catalog: gyrocal_serve::CatalogSource::None,
        catalog_url: None,
        stale_after: None,
    };
    std::thread::Builder::new()
        .name("gyrocal-serve".into())
        .spawn(move || {
            let rt = match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(rt) => rt,
                Err(e) => {
                    tracing::warn!("the web view cannot start its runtime: {e}");
                    return;
                }
            };
            rt.block_on(async move {
                match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => {
                        if let Err(e) = gyrocal_serve::App::new(cfg).serve(l).await {
                            tracing::warn!("the web view stopped: {e}");
                        }
                    }
                    Err(e) => tracing::warn!("the web view cannot listen: {e}"),
                }
            });
        })?;
    Ok(local)
}

/// After the run directory is open, before the first step: `--serve` starts the view over
/// the run's root and prints the run's page; the station's `serve` key prints the lab view's
/// page of the run. A view that cannot start is a warning: the run goes on.
pub(super) fn announce(args: &RunArgs, station_serve: Option<&str>, dir: &Path) {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if let Some(text) = &args.serve {
        let root = match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let started = serve_addr(text).and_then(|(addr, token)| {
            let with_token = token.is_some();
            start_server(addr, token, root).map(|a| (a, with_token))
        });
        match started {
            Ok((local, with_token)) => {
                let host = match local.ip() {
                    std::net::IpAddr::V6(ip) => format!("[{ip}]"),
                    ip => ip.to_string(),
                };
                let page = format!(
                    "http://{host}:{}/run/0/{}",
                    local.port(),
                    gyrocal_serve::runs::encode(&name)
                );
                if with_token {
                    say!("live view: {page} (open /login?token=… first)");
                } else {
                    say!("live view: {page}");
                }
            }
            Err(e) => {
                say!("gyrocal: warning: the live view did not start ({e:#}); the run goes on")
            }
        }
    }
    if let Some(base) = station_serve {
        say!(
            "live view: {base}/live/{}/{} (the station's serve)",
            gyrocal_serve::runs::encode(&gyrocal_files::rundir::host_name()),
            gyrocal_serve::runs::encode(&name)
        );
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use gyrocal_run::live::StepSummary;

    /// A state too long for a row keeps its newest steps and its counts.
    #[test]
    fn a_long_live_state_is_trimmed_to_the_row_cap_keeping_the_newest_steps() {
        let dir = tempfile::tempdir().unwrap();
        let live = LiveFile::new(
            dir.path(),
            LiveHeader {
                run_id: "r".into(),
                steps: 5000,
                ..LiveHeader::default()
            },
        );
        let mut s = live.handle().state();
        s.steps_done = 5000;
        s.step_summaries = (1..=5000)
            .map(|i| StepSummary {
                number: i,
                rate_dps: i as f64,
                volts: 0.1,
                volts_std: Some(1e-4),
                n: 10,
                overloads: 0,
                t_end_s: i as f64,
            })
            .collect();
        let row = row_of(&s);
        assert!(
            row.state_json.len() <= MAX_STATE_JSON,
            "{}",
            row.state_json.len()
        );
        assert_eq!(row.steps_done, 5000);
        let back: LiveState = serde_json::from_str(&row.state_json).unwrap();
        assert!(!back.step_summaries.is_empty());
        assert_eq!(back.step_summaries.last().unwrap().number, 5000);
    }
}
