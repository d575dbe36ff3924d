//! `gyrocal history SERIAL`: a gyro's complete calibrations over time, from the catalog: the
//! results with their uncertainties, the repeatability from calibration to calibration, and
//! (`-o FILE.html`) a trend plot per quantity with its limits and control band.

use std::path::PathBuf;

use clap::Args;

use crate::cmd::catalog::{CatalogOpt, open, user_error};

/// Arguments of `gyrocal history`.
#[derive(Debug, Args)]
pub struct HistoryArgs {
    /// The gyro's serial number.
    #[arg(value_name = "SERIAL")]
    pub serial: String,
    /// Print JSON (calibrations, repeatability, trends, warnings).
    #[arg(long)]
    pub json: bool,
    /// Write the history as an HTML page with trend plots to FILE.
    #[arg(short = 'o', long = "out", alias = "output", value_name = "FILE.html")]
    pub output: Option<PathBuf>,
    /// Count runs on the simulated bench too (left out by default).
    #[arg(long)]
    pub include_simulated: bool,
    #[command(flatten)]
    catalog: CatalogOpt,
}

/// A value ± its expanded uncertainty, rounded as on the certificate.
fn sci(v: Option<f64>, u: Option<f64>) -> String {
    match (v, u) {
        (Some(v), Some(u)) => gyrocal_fit::display::value_pm_u(v, Some(u), ""),
        (Some(v), None) => gyrocal_fit::display::significant(v, 7),
        _ => "—".to_string(),
    }
}

/// Runs `gyrocal history`.
pub fn run(args: &HistoryArgs) -> anyhow::Result<u8> {
    let (rt, catalog) = open(&args.catalog)?;
    let h = rt
        .block_on(catalog.history(&args.serial, args.include_simulated))
        .map_err(user_error)?;
    rt.block_on(catalog.close());
    for w in &h.warnings {
        eprintln!("gyrocal: warning: {w}");
    }
    if let Some(path) = &args.output {
        let html = gyrocal_report::history::render(&h);
        std::fs::write(path, html)
            .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", path.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&h)?);
        return Ok(0);
    }
    if h.calibrations.is_empty() {
        println!(
            "no complete calibrations of {} in {}{}",
            h.serial,
            catalog.url(),
            if args.include_simulated {
                ""
            } else {
                " (simulated runs left out: --include-simulated)"
            }
        );
        return Ok(0);
    }
    let sweeps: Vec<_> = h
        .calibrations
        .iter()
        .filter(|c| c.run.kind != "drift")
        .collect();
    if !sweeps.is_empty() {
        println!(
            "{:<20} {:<26} {:<22} {:<13} {:<3} DIRECTORY",
            "STARTED (UTC)", "K ± U V/(°/s)", "BIAS ± U °/h", "VERDICT", "SIM"
        );
    }
    for c in &sweeps {
        let r = c.results.clone().unwrap_or_default();
        println!(
            "{:<20} {:<26} {:<22} {:<13} {:<3} {}",
            c.run.started_utc.chars().take(19).collect::<String>(),
            sci(r.scale_factor, r.u_scale_factor),
            sci(r.bias_dph, r.u_bias_dph),
            c.run.verdict.as_deref().unwrap_or("—"),
            if c.run.simulated { "yes" } else { "" },
            c.run.directory
        );
    }
    let drift: Vec<_> = h
        .calibrations
        .iter()
        .filter(|c| c.results.as_ref().is_some_and(|r| r.arw_deg_rt_h.is_some()))
        .collect();
    if !drift.is_empty() {
        println!(
            "{}drift tests:\n{:<20} {:<22} {:<22} {:<22} {:<22} DIRECTORY",
            if sweeps.is_empty() { "" } else { "\n" },
            "STARTED (UTC)",
            "N ± U °/√h",
            "B ± U °/h",
            "K ± U °/h/√h",
            "BIAS ± U °/h"
        );
        for c in drift {
            let r = c.results.clone().unwrap_or_default();
            println!(
                "{:<20} {:<22} {:<22} {:<22} {:<22} {}",
                c.run.started_utc.chars().take(19).collect::<String>(),
                sci(r.arw_deg_rt_h, r.u_arw_deg_rt_h),
                sci(r.bias_instability_dph, r.u_bias_instability_dph),
                sci(r.rrw_dph_rt_h, r.u_rrw_dph_rt_h),
                sci(r.drift_bias_dph, r.u_drift_bias_dph),
                c.run.directory
            );
        }
    }
    if sweeps.is_empty() {
        return Ok(0);
    }
    let rep = &h.repeatability;
    // with several plans, the repeatability is the latest plan's (the catalog's History)
    let of = match rep.plan.and_then(|p| h.plans.get(p)) {
        Some(p) if rep.other_plans > 0 => format!(
            " of plan \"{}\" ({} of other plans left out)",
            p.name, rep.other_plans
        ),
        _ => String::new(),
    };
    match (rep.scale_factor_ppm, rep.bias_dph) {
        (Some(k), Some(b)) => println!(
            "repeatability over {} calibrations{of}: K {k:.2} ppm, bias {b:.4} °/h",
            rep.n
        ),
        (Some(k), None) => println!(
            "repeatability over {} calibrations{of}: K {k:.2} ppm",
            rep.n
        ),
        _ => println!("repeatability: needs two calibrations or more"),
    }
    Ok(0)
}
