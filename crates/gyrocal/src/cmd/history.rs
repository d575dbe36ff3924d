//! `gyrocal history SERIAL`: a gyro's complete calibrations over time, from the catalog: the
//! results with their uncertainties, the repeatability from calibration to calibration, and
//! (`-o FILE.html`) a trend plot per quantity with its limits and control band.
//!
//! A temperature series (issue 26) is a calibration of its own kind: its table gives the
//! sensitivities of K and of the bias to temperature with their U (k = 2), the range measured
//! and the hysteresis, and the lines under it how each sensitivity moved from the gyro's first
//! series to its latest (the trends the catalog computes, as it does for K).

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
        .filter(|c| c.run.kind != "drift" && !is_series(c))
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
    let drift: Vec<&gyrocal_catalog::Calibration> = h
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
        for c in &drift {
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
    print_series(&h, !sweeps.is_empty() || !drift.is_empty());
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

/// Whether `c` is a temperature series (its kind, or the series' figures the catalog holds).
fn is_series(c: &gyrocal_catalog::Calibration) -> bool {
    c.series.is_some() || c.run.kind == gyrocal_files::station::SERIES_KIND
}

/// The series' quantities whose trends the terminal states (name, words).
const SERIES_TRENDS: [(&str, &str); 4] = [
    ("k_tempco_ppm_per_c", "K's temperature sensitivity"),
    (
        "bias_tempco_dph_per_c",
        "the bias's temperature sensitivity",
    ),
    ("hysteresis_k_ppm", "K's thermal hysteresis"),
    ("hysteresis_bias_dph", "the bias's thermal hysteresis"),
];

/// The temperature series of the history: one line each with the sensitivities ± U, the range
/// and the hysteresis, then each sensitivity's trend from the first series to the latest.
fn print_series(h: &gyrocal_catalog::History, after_other_tables: bool) {
    let series: Vec<_> = h.calibrations.iter().filter(|c| is_series(c)).collect();
    if series.is_empty() {
        return;
    }
    println!(
        "{}temperature series:\n{:<20} {:<24} {:<24} {:<17} {:<22} {:<3} DIRECTORY",
        if after_other_tables { "\n" } else { "" },
        "STARTED (UTC)",
        "K SENS. ± U ppm/°C",
        "BIAS SENS. ± U °/h/°C",
        "RANGE °C",
        "HYSTERESIS K, BIAS",
        "SIM"
    );
    for c in &series {
        let Some(s) = &c.series else {
            println!(
                "{:<20} (not analysed: no series.json in the catalog)   {}",
                c.run.started_utc.chars().take(19).collect::<String>(),
                c.run.directory
            );
            continue;
        };
        let range = match (s.t_min_c, s.t_max_c) {
            (Some(a), Some(b)) => format!("{a:.1} .. {b:.1}"),
            _ => "—".to_string(),
        };
        let hysteresis = match (s.hysteresis_k_ppm, s.hysteresis_bias_dph) {
            (None, None) => "none revisited".to_string(),
            (k, b) => format!(
                "{} ppm, {} °/h",
                k.map_or("—".to_string(), |v| format!("{v:.1}")),
                b.map_or("—".to_string(), |v| gyrocal_fit::display::significant(
                    v, 3
                ))
            ),
        };
        println!(
            "{:<20} {:<24} {:<24} {:<17} {:<22} {:<3} {}",
            c.run.started_utc.chars().take(19).collect::<String>(),
            sci(s.k_tempco_ppm_per_c, s.u_k_tempco_ppm_per_c),
            sci(s.bias_tempco_dph_per_c, s.u_bias_tempco_dph_per_c),
            range,
            hysteresis,
            if c.run.simulated { "yes" } else { "" },
            c.run.directory
        );
    }
    for (name, words) in SERIES_TRENDS {
        let Some(t) = h.trends.iter().find(|t| t.quantity == name) else {
            continue;
        };
        let (Some(first), Some(latest)) = (t.points.first(), t.points.last()) else {
            continue;
        };
        if t.points.len() < 2 {
            println!(
                "trend of {words}: one series so far ({} {})",
                sci(Some(latest.value), latest.expanded_uncertainty),
                t.unit
            );
            continue;
        }
        let change = latest.value - first.value;
        // a change within the two values' U (k = 2, combined) is not a change one can tell
        let u = match (first.expanded_uncertainty, latest.expanded_uncertainty) {
            (Some(a), Some(b)) => Some(a.hypot(b)),
            _ => None,
        };
        let verdict = match u {
            Some(u) if change.abs() <= u => format!(
                ", within the U of the two: {} {}",
                gyrocal_fit::display::significant(u, 2),
                t.unit
            ),
            Some(u) => format!(
                ", MORE than the U of the two: {} {}",
                gyrocal_fit::display::significant(u, 2),
                t.unit
            ),
            None => String::new(),
        };
        println!(
            "trend of {words} over {} series: {} → {} {} (change {}{verdict}){}",
            t.points.len(),
            gyrocal_fit::display::trimmed(first.value, 4),
            gyrocal_fit::display::trimmed(latest.value, 4),
            t.unit,
            signed(change),
            if t.latest_outside_band {
                "; the latest is OUTSIDE its control band"
            } else {
                ""
            }
        );
    }
}

/// A change with its sign (`+3.00`, `−0.300`), to 3 significant digits.
fn signed(v: f64) -> String {
    let text = gyrocal_fit::display::significant(v.abs(), 3);
    if v < 0.0 {
        format!("−{text}")
    } else {
        format!("+{text}")
    }
}
