//! `gyrocal serve`: the lab's live view in a browser (see the gyrocal-serve crate): the runs
//! under one or more roots as they proceed (each run's `live.json`), their pages and verdicts,
//! and each gyro's history from the catalog. Read-only.
//!
//! With a PostgreSQL catalog (`--catalog postgres://...`), the lab's shared one, it also
//! listens to the runs every bench publishes there (`LISTEN gyrocal_live`) and shows them
//! beside its roots' runs: one view of every bench, roots or not.
//!
//! The catalog need not answer when the view starts (a lab starts it at boot, often before
//! its PostgreSQL): the view then serves its roots' runs at once, says once that the catalog
//! does not answer yet, and tries it again in the background (2 s doubling to 60 s, see
//! `gyrocal_serve::catalog`) until it opens, which it says once too; meanwhile a gyro page says
//! the catalog is not reachable yet. Any failure to open is tried again, an SQLite file's too
//! (missing until the first run creates it, unreadable until its permissions are fixed,
//! damaged until `gyrocal catalog rebuild` replaces it): waiting may mend those. A catalog URL
//! that does not parse is refused at once (exit 2), naming where it came from: waiting cannot
//! mend it. The URL is only ever shown redacted (no password).
//!
//! Loopback by default; `--bind` to another address needs `--token` (or
//! `$GYROCAL_SERVE_TOKEN`): a browser then opens `/login?token=TOKEN` once (a cookie), a
//! script sends `Authorization: Bearer TOKEN`.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use clap::Args;
use gyrocal_catalog::{Catalog, CatalogUrl, OpenOptions};
use gyrocal_serve::{CatalogNow, CatalogSource};

use crate::BadInput;
use crate::cmd::catalog::CatalogOpt;

/// How long the first try to open the catalog may take before the view starts without it
/// (and tries again in the background): short, so a catalog that does not answer delays
/// nothing a lab would notice.
const FIRST_TRY: std::time::Duration = std::time::Duration::from_secs(2);

/// The environment variable that may hold the token (kept out of `ps`).
pub const TOKEN_ENV: &str = "GYROCAL_SERVE_TOKEN";

/// Arguments of `gyrocal serve`.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// A directory of run directories (repeatable). Default: `runs`, where `gyrocal run` puts
    /// a run without --out (with a PostgreSQL catalog, only when it exists: the catalog's
    /// live runs may be all there is to show).
    #[arg(long = "root", value_name = "DIR")]
    pub roots: Vec<PathBuf>,
    /// The address to listen on. Anything but loopback needs a token.
    #[arg(long, value_name = "ADDR", default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub bind: IpAddr,
    /// The TCP port (0: any free port; the URL printed says which).
    #[arg(long, value_name = "PORT", default_value_t = 8737)]
    pub port: u16,
    /// The token every request must carry (default $GYROCAL_SERVE_TOKEN); required off
    /// loopback.
    #[arg(long, value_name = "TOKEN")]
    pub token: Option<String>,
    /// A running run whose live state has not changed for this long is shown stale (its
    /// process hung, or its host is gone: a run on this host whose process ended is stale at
    /// once).
    #[arg(long, value_name = "SECS", default_value_t = gyrocal_serve::runs::STALE_AFTER.as_secs_f64(), value_parser = positive_secs)]
    pub stale_after: f64,
    /// Serve without the catalog (no gyro history pages). `--catalog off` or
    /// GYROCAL_CATALOG=off too.
    #[arg(long)]
    pub no_catalog: bool,
    #[command(flatten)]
    catalog: CatalogOpt,
}

/// `--stale-after`: a finite number of seconds > 0.
fn positive_secs(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v < 1e9 => Ok(v),
        _ => Err(format!("{s:?}: a number of seconds > 0 (for example 120)")),
    }
}

/// `off` or `none`: no catalog.
fn is_off(s: &str) -> bool {
    matches!(s.trim(), "off" | "none")
}

/// The catalog to serve: `--catalog`, `$GYROCAL_CATALOG`, the station file's `catalog`, the
/// default SQLite file; `None` with `--no-catalog` or `off`. A URL that does not parse is
/// bad input naming where it came from; no default (neither HOME nor XDG_DATA_HOME) is said
/// and the view goes without.
fn catalog_url(args: &ServeArgs) -> anyhow::Result<Option<CatalogUrl>> {
    if args.no_catalog {
        return Ok(None);
    }
    let given = |from: &str, text: &str| -> anyhow::Result<Option<CatalogUrl>> {
        if is_off(text) {
            return Ok(None);
        }
        CatalogUrl::parse(text)
            .map(Some)
            .map_err(|e| BadInput(format!("{from}: {e}")).into())
    };
    if let Some(flag) = args
        .catalog
        .catalog
        .as_deref()
        .filter(|s| !s.trim().is_empty())
    {
        return given("--catalog", flag);
    }
    if let Some(env) = std::env::var(gyrocal_catalog::CATALOG_ENV)
        .ok()
        .filter(|s| !s.trim().is_empty())
    {
        return given(&format!("${}", gyrocal_catalog::CATALOG_ENV), &env);
    }
    match gyrocal_files::station::Station::resolve(None) {
        Ok(Some((path, station))) => {
            if let Some(text) = station.catalog.filter(|s| !s.trim().is_empty()) {
                return given(&format!("{}: catalog", path.display()), &text);
            }
        }
        Ok(None) => {}
        Err(e) => eprintln!("gyrocal: warning: station: {e} (its catalog setting is not used)"),
    }
    match CatalogUrl::default_sqlite() {
        Ok(url) => Ok(Some(url)),
        Err(e) => {
            eprintln!("gyrocal: warning: no catalog ({e}); gyro pages are off");
            Ok(None)
        }
    }
}

/// What the view says once its catalog is open.
fn say_open(url: &CatalogUrl, catalog: &Catalog) {
    if catalog.carries_live() {
        eprintln!(
            "gyrocal serve: the catalog {} answers: gyro pages on, showing the live runs of every bench that publishes to it",
            url.redacted()
        );
    } else {
        eprintln!(
            "gyrocal serve: the catalog {} answers: gyro pages on",
            url.redacted()
        );
    }
}

/// Runs `gyrocal serve` until interrupted.
pub fn run(args: &ServeArgs) -> anyhow::Result<u8> {
    let token = args
        .token
        .clone()
        .or_else(|| std::env::var(TOKEN_ENV).ok())
        .filter(|t| !t.is_empty());
    let addr = SocketAddr::new(args.bind, args.port);
    gyrocal_serve::check_bind(&addr, token.as_deref()).map_err(|e| BadInput(e.to_string()))?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let catalog_url = catalog_url(args)?;
    let catalog = match &catalog_url {
        None => CatalogSource::None,
        Some(url) => {
            let first = OpenOptions {
                connect_timeout: FIRST_TRY,
                create: false,
                ..OpenOptions::default()
            };
            match rt.block_on(Catalog::open_with(url, &first)) {
                Ok(c) => {
                    say_open(url, &c);
                    CatalogSource::Open(c)
                }
                Err(e) => {
                    // the error names the catalog redacted (see CatalogError)
                    eprintln!(
                        "gyrocal: warning: the catalog does not answer yet ({e}); serving without it and trying it again ({} s, doubling to {} s between tries) until it answers",
                        gyrocal_serve::catalog::RETRY_FIRST.as_secs(),
                        gyrocal_serve::catalog::RETRY_MAX.as_secs()
                    );
                    CatalogSource::Later(url.clone())
                }
            }
        }
    };
    // a PostgreSQL catalog carries the live runs of every bench, whether it answers yet or not
    let live = matches!(catalog_url, Some(CatalogUrl::Postgres(_)));
    let roots = if !args.roots.is_empty() {
        args.roots.clone()
    } else if live && !std::path::Path::new("runs").is_dir() {
        Vec::new()
    } else {
        vec![PathBuf::from("runs")]
    };
    for r in &roots {
        if !r.is_dir() {
            eprintln!(
                "gyrocal: warning: {}: not a directory (yet); its runs appear once it is",
                r.display()
            );
        }
    }
    let url_later = match &catalog {
        CatalogSource::Later(url) => Some(url.clone()),
        _ => None,
    };
    let cfg = gyrocal_serve::ServeConfig {
        roots,
        token: token.clone(),
        catalog,
        catalog_url,
        stale_after: Some(std::time::Duration::from_secs_f64(args.stale_after)),
    };
    rt.block_on(async move {
        let listener = gyrocal_serve::bind(addr, token.as_deref()).await?;
        let local = listener.local_addr()?;
        let host = match local.ip() {
            IpAddr::V6(ip) => format!("[{ip}]"),
            ip => ip.to_string(),
        };
        if token.is_some() {
            println!(
                "gyrocal serve: http://{host}:{}/login?token=… (the token you gave)",
                local.port()
            );
        } else {
            println!("gyrocal serve: http://{host}:{}/", local.port());
        }
        let app = gyrocal_serve::App::new(cfg);
        if let Some(url) = url_later {
            let mut now = app.catalog_now();
            tokio::spawn(async move {
                if let Ok(state) = now.wait_for(|s| matches!(s, CatalogNow::Open(_))).await
                    && let CatalogNow::Open(c) = &*state
                {
                    say_open(&url, c);
                }
            });
        }
        tokio::select! {
            r = app.serve(listener) => r.map_err(anyhow::Error::from),
            _ = tokio::signal::ctrl_c() => Ok(()),
        }
    })?;
    Ok(0)
}
