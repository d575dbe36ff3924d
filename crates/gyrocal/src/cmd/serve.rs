//! `gyrocal serve`: the lab's live view in a browser (see the gyrocal-serve crate): the runs
//! under one or more roots as they proceed (each run's `live.json`), their pages and verdicts,
//! and each gyro's history from the catalog. Read-only.
//!
//! With a PostgreSQL catalog (`--catalog postgres://...`), the lab's shared one, it also
//! listens to the runs every bench publishes there (`LISTEN gyrocal_live`) and shows them
//! beside its roots' runs: one view of every bench, roots or not.
//!
//! Loopback by default; `--bind` to another address needs `--token` (or
//! `$GYROCAL_SERVE_TOKEN`): a browser then opens `/login?token=TOKEN` once (a cookie), a
//! script sends `Authorization: Bearer TOKEN`.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use clap::Args;

use crate::BadInput;
use crate::cmd::catalog::CatalogOpt;

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
    /// Serve without the catalog (no gyro history pages).
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
    let (catalog, catalog_url) = if args.no_catalog {
        (None, None)
    } else {
        match crate::cmd::catalog::open_in(&rt, &args.catalog) {
            Ok(c) => {
                let url = c.url().clone();
                (Some(c), Some(url))
            }
            Err(e) => {
                eprintln!("gyrocal: warning: no catalog ({e}); gyro pages are off");
                (None, None)
            }
        }
    };
    let live = catalog.as_ref().is_some_and(|c| c.carries_live());
    let roots = if !args.roots.is_empty() {
        args.roots.clone()
    } else if live && !std::path::Path::new("runs").is_dir() {
        Vec::new()
    } else {
        vec![PathBuf::from("runs")]
    };
    if let Some(url) = catalog_url.as_ref().filter(|_| live) {
        eprintln!(
            "gyrocal serve: showing the live runs of every bench that publishes to {}",
            url.redacted()
        );
    }
    for r in &roots {
        if !r.is_dir() {
            eprintln!(
                "gyrocal: warning: {}: not a directory (yet); its runs appear once it is",
                r.display()
            );
        }
    }
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
        tokio::select! {
            r = app.serve(listener) => r.map_err(anyhow::Error::from),
            _ = tokio::signal::ctrl_c() => Ok(()),
        }
    })?;
    Ok(0)
}
