//! `gyrocal runs`: the runs in the catalog, newest first, as a table or JSON.

use clap::Args;
use gyrocal_catalog::RunFilter;

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
    if args.json {
        println!("{}", serde_json::to_string_pretty(&runs)?);
        return Ok(0);
    }
    if runs.is_empty() {
        println!("no runs in {}", catalog.url());
        return Ok(0);
    }
    println!(
        "{:<20} {:<12} {:<9} {:<13} {:>12} {:<10} {:<3} DIRECTORY",
        "STARTED (UTC)", "SERIAL", "STATUS", "VERDICT", "K V/(°/s)", "STATION", "SIM"
    );
    for r in &runs {
        let k = r
            .results
            .as_ref()
            .and_then(|x| x.scale_factor)
            .map_or("—".to_string(), |k| format!("{k:.7}"));
        println!(
            "{:<20} {:<12} {:<9} {:<13} {:>12} {:<10} {:<3} {}",
            r.run.started_utc.chars().take(19).collect::<String>(),
            r.run.dut_serial.as_deref().unwrap_or("—"),
            r.run.status,
            r.run.verdict.as_deref().unwrap_or("—"),
            k,
            r.run.station_id.as_deref().unwrap_or("—"),
            if r.run.simulated { "yes" } else { "" },
            r.run.directory
        );
    }
    Ok(0)
}
