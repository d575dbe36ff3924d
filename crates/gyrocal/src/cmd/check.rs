//! `gyrocal check PLAN`: validate a plan against the instruments' limits and print its
//! schedule with the duration each step will take, from the instruments' timing models. It
//! warns (on stderr; exit 0) about the default models the schedule's data cannot determine,
//! which the fit at the end of the run will skip, by the fit's own rule
//! ([`gyrocal_fit::unsupported_models`]).

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Args;
use gyrocal_files::Plan;
use gyrocal_run::estimate::{self, Estimate};

use crate::BadInput;

/// Arguments of `gyrocal check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The test plan (TOML).
    pub plan: PathBuf,
    /// Print exactly one JSON document on stdout (the schedule, the estimate, the warnings)
    /// instead of the human text.
    #[arg(long)]
    pub json: bool,
    /// Also open each instrument, identify it, read the table's mode and rate (nothing
    /// moves). Both ports are probed; when one fails, say who answered there (ports given the
    /// wrong way round are said as swapped) and, when nothing did, what to check on that
    /// link. With a station file, its serials are compared with the instruments'. A plan with
    /// a [chamber] (a temperature series) has its chamber probed too: identified (units,
    /// decimal places, range) and read (air and gyro temperature, setpoint, mode, alarms),
    /// nothing written, and with a station file its controller is compared with the
    /// station's [chamber] model. Exit 1 when an instrument is not found on its port, or the
    /// chamber has an alarm latched (a run would stop at once).
    #[arg(long)]
    pub probe: bool,
    /// With --probe: the multimeter's port instead of the plan's.
    #[arg(long, value_name = "PORT", requires = "probe")]
    pub dmm_port: Option<String>,
    /// With --probe: the rate table's port instead of the plan's.
    #[arg(long, value_name = "PORT", requires = "probe")]
    pub table_port: Option<String>,
    /// With --probe: the thermal chamber's port instead of the plan's `[chamber] port` (a
    /// serial device for Modbus RTU or the Espec's text, tcp://HOST:PORT for Modbus TCP).
    #[arg(long, value_name = "PORT", requires = "probe")]
    pub chamber_port: Option<String>,
    /// The station file to check with the plan (else $GYROCAL_STATION, else
    /// ~/.config/gyrocal/station.toml when it exists), as `gyrocal run` would read it: a bad
    /// file, or a calibration dated after today, exits 2; a missing [multimeter] (or, for a
    /// plan with a table, [table]) section is a warning.
    #[arg(long, value_name = "FILE")]
    pub station: Option<PathBuf>,
}

/// Reads and validates a plan; a bad plan is the user's to fix (exit 2). The plan's own
/// validation is complete (ports parsed into the link's type, the meter's settings checked
/// against the named model's facts): what `check` adds needs the station file or a live port.
pub fn load_plan(path: &std::path::Path) -> anyhow::Result<Plan> {
    Plan::from_file(path).map_err(|e| BadInput(e.to_string()).into())
}

/// Puts `--dmm-port` and `--table-port` in place of the plan's ports, each parsed as the
/// plan's own is (a bad one is the user's to fix, exit 2).
pub fn override_ports(
    plan: &mut Plan,
    dmm: Option<&str>,
    table: Option<&str>,
) -> anyhow::Result<()> {
    if let Some(p) = dmm {
        let port =
            gyrocal_files::Port::parse(p).map_err(|e| BadInput(format!("--dmm-port: {e}")))?;
        plan.set_dmm_port(port);
    }
    if let Some(p) = table {
        let port =
            gyrocal_files::Port::parse(p).map_err(|e| BadInput(format!("--table-port: {e}")))?;
        plan.set_table_port(port);
    }
    Ok(())
}

/// Runs `gyrocal check`.
pub fn run(args: &CheckArgs) -> anyhow::Result<()> {
    let mut plan = load_plan(&args.plan)?;
    override_ports(
        &mut plan,
        args.dmm_port.as_deref(),
        args.table_port.as_deref(),
    )?;
    // --chamber-port in place of the plan's, as `gyrocal run` takes it (the series' line
    // then names the port probed)
    let chamber_port = match &args.chamber_port {
        Some(p) => Some(
            p.parse::<gyrocal_link::PortSpec>()
                .map_err(|e| BadInput(format!("--chamber-port {p}: {e}")))?,
        ),
        None => None,
    };
    if let Some(spec) = &chamber_port
        && plan.chamber().is_some()
    {
        plan.set_chamber_port(spec.clone());
    }
    let steps = plan.schedule();
    let timing = crate::instruments::meter_timing(&plan);
    let est = estimate::estimate(&plan, &steps, 0.0, timing.as_ref());
    let mut warnings = gyrocal_analysis::plan_warnings(&plan, &args.plan);
    if est.total > std::time::Duration::from_secs(24 * 3600) {
        warnings.push(format!(
            "{}: the plan runs about {}, longer than a day: is that meant (samples_per_rate, repeat, settle_s)?",
            args.plan.display(),
            hms(est.total.as_secs_f64())
        ));
    }
    // the station `gyrocal run` would use, read the same way (a bad one is bad input)
    let station = gyrocal_files::station::Station::resolve(args.station.as_deref())
        .map_err(|e| BadInput(format!("station: {e}")))?;
    let needs = gyrocal_files::station::Needs::of_plan(&plan);
    if let Some((path, station)) = &station {
        warnings.extend(station_warnings(station, path, needs));
        // `gyrocal run` refuses these (unless --allow-expired): said here before the day
        let today = jiff::Zoned::now().date();
        for o in station.overdue_for(today, needs) {
            warnings.push(format!(
                "station {}: {o} (today is {today}): `gyrocal run` will refuse the plan unless \
                 started with --allow-expired, which the report records as a deviation",
                station.id
            ));
        }
    }
    if chamber_port.is_some() && plan.chamber().is_none() {
        warnings.push(format!(
            "{}: the plan has no [chamber] (it is not a temperature series): --chamber-port \
             is not probed",
            args.plan.display()
        ));
    }
    let (probe, chamber) = if args.probe {
        use anyhow::Context as _;
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("starting the async runtime")?;
        let flags = crate::cmd::probe::PortFlags {
            dmm: args.dmm_port.is_some(),
            table: args.table_port.is_some(),
        };
        // all three at once: a failure on one does not hide the others
        let (probe, chamber) = rt.block_on(async {
            tokio::join!(
                crate::cmd::probe::probe(&plan, flags),
                crate::cmd::probe::chamber::probe(&plan, chamber_port.as_ref()),
            )
        });
        (Some(probe), chamber)
    } else {
        (None, None)
    };
    // the station's serials against the instruments' identities, once both are known
    let mut serials = match (&probe, &station) {
        (Some(Ok(found)), Some((_, station))) => crate::cmd::probe::serial_checks(station, found),
        _ => Vec::new(),
    };
    // the chamber's controller against the station's [chamber] record, as `gyrocal run`
    // compares it (the model: the controller reports no serial)
    if let (Some(Ok(found)), Some((_, station))) = (&chamber, &station) {
        serials.extend(station.check_chamber(Some(found.model.as_str()), None));
    }
    for c in serials.iter().filter(|c| c.is_mismatch()) {
        if let Some((_, station)) = &station {
            warnings.push(c.words(&station.id));
        }
    }
    if args.json {
        let mut doc = json(&plan, &args.plan, &est, &warnings);
        if let Some(p) = &probe {
            doc["probe"] = match p {
                Ok(f) => serde_json::json!({
                    "answered": true,
                    "dmm": f.dmm,
                    "table": f.table,
                    "table_mode": f.table_mode,
                    "table_rate_dps": f.table_rate_dps,
                }),
                Err(e) => {
                    let mut p = serde_json::json!({ "answered": false, "error": format!("{e:#}") });
                    if let Some(pe) = e.downcast_ref::<crate::cmd::probe::ProbeError>() {
                        p["diagnosis"] = pe.headline().into();
                        p["swapped"] =
                            (pe.kind() == crate::cmd::probe::ProbeErrorKind::Swapped).into();
                        p["ports"] = pe.ports_json();
                    }
                    p
                }
            };
            if let (Some((_, station)), false) = (&station, serials.is_empty()) {
                doc["probe"]["serials"] = serials
                    .iter()
                    .map(|c| {
                        serde_json::json!({
                            "role": c.role(),
                            "result": c.key(),
                            "text": c.words(&station.id),
                        })
                    })
                    .collect();
            }
        }
        if let Some(c) = &chamber {
            doc["probe"]["chamber"] = match c {
                Ok(found) => found.json(),
                Err(e) => e.json(),
            };
        }
        println!("{doc:#}");
    } else {
        print!("{}", render(&plan, &args.plan, &est));
        for w in &warnings {
            eprintln!("gyrocal: warning: {w}");
        }
        if let Some(Ok(found)) = &probe {
            println!();
            println!("probe: multimeter {}", found.dmm);
            println!(
                "probe: rate table {} (mode {}, {:+.4} °/s)",
                found.table, found.table_mode, found.table_rate_dps
            );
            if let Some((_, station)) = &station {
                for c in serials.iter().filter(|c| !c.is_mismatch()) {
                    println!("station: {}", c.words(&station.id));
                }
            }
        }
    }
    if !args.json
        && let Some(c) = &chamber
    {
        let found = match c {
            Ok(found) => Some(found),
            Err(e) => e.found.as_ref(),
        };
        if let Some(f) = found {
            println!("probe: chamber {} at {} ({})", f.model, f.port, f.detail);
            println!("probe: chamber reads {}", f.reading_words());
        }
    }
    // a silent instrument is an error (exit 1) whatever the output format; the chamber's
    // failure is said too when the meter's or the table's is the one returned
    match (probe, chamber) {
        (Some(Err(e)), Some(Err(c))) => {
            eprintln!("gyrocal: {c}");
            Err(e)
        }
        (Some(Err(e)), _) => Err(e),
        (_, Some(Err(c))) => Err(c.into()),
        _ => Ok(()),
    }
}

/// One line per section a run with `needs` (its plan's) needs and the station file at `path`
/// lacks: the certificate cannot name that instrument or its calibration. Said by `gyrocal
/// check` and at the start of `gyrocal run`.
pub fn station_warnings(
    station: &gyrocal_files::station::Station,
    path: &std::path::Path,
    needs: gyrocal_files::station::Needs,
) -> Vec<String> {
    station
        .missing_sections(needs)
        .into_iter()
        .map(|section| {
            let what = match section {
                "multimeter" => "multimeter",
                "chamber" => "thermal chamber",
                _ => "rate table",
            };
            format!(
                "station {} ({}) has no [{section}] section: the certificate will not name the \
                 {what}, its serial or its calibration (no traceability for it); add the \
                 section to the station file",
                station.id,
                path.display()
            )
        })
        .collect()
}

/// Formats seconds as `1 h 02 min 03.4 s`, `2 min 03.4 s` or `3.42 s`.
pub fn hms(s: f64) -> String {
    if !s.is_finite() {
        return "?".into();
    }
    let h = (s / 3600.0).floor();
    let m = ((s - h * 3600.0) / 60.0).floor();
    let sec = s - h * 3600.0 - m * 60.0;
    if h > 0.0 {
        format!("{h:.0} h {m:02.0} min {sec:04.1} s")
    } else if m > 0.0 {
        format!("{m:.0} min {sec:04.1} s")
    } else {
        format!("{sec:.2} s")
    }
}

/// The `--json` document: what `render` says, for scripts. Steps carry `step_no` and `pass_no`,
/// counted from 1 like the terminal and the run directory's files (`step_no` 3 is "step 3 of
/// 19" and the `step_no` 3 rows of samples.csv and steps.csv).
fn json(
    plan: &Plan,
    path: &std::path::Path,
    est: &Estimate,
    warnings: &[String],
) -> serde_json::Value {
    let steps: Vec<serde_json::Value> = est
        .steps
        .iter()
        .map(|s| {
            serde_json::json!({
                "step_no": s.step.index + 1,
                "pass_no": s.step.pass + 1,
                "rate_dps": s.step.rate_dps,
                "samples": s.samples,
                "ramp_s": s.ramp.as_secs_f64(),
                "dwell_s": s.settle.as_secs_f64(),
                "acquire_s": s.acquire.as_secs_f64(),
            })
        })
        .collect();
    let mut doc = serde_json::json!({
        "plan": path,
        "name": plan.name(),
        "hash": plan.hash(),
        // a drift record on a bench without a table has none
        "table": plan.has_table().then(|| serde_json::json!({
            "dialect": plan.table().dialect.as_str(),
            "port": plan.table().port.to_string(),
        })),
        "dmm": {
            "model": plan.dmm().model.as_str(),
            "port": plan.dmm().port.to_string(),
            "reading_time_s": est.reading_time.as_secs_f64(),
            "acquisition": est.acquisition,
        },
        "steps": steps,
        "readings": est.steps.iter().map(|s| s.samples).sum::<u64>(),
        "estimated_s": est.total.as_secs_f64(),
        "bound_s": est.bound.as_secs_f64(),
        "warmup": plan.warmup().map(|w| serde_json::json!({
            "window_s": w.window.as_secs_f64(),
            "tolerance_v": w.tolerance_v,
            "max_s": w.max.as_secs_f64(),
        })),
        "warnings": warnings,
    });
    // the kind's own settings, under its section's name (`drift`)
    if let Some(k) = plan.kind_summary() {
        doc[k.key] = k.json;
    }
    doc
}

fn render(plan: &Plan, path: &std::path::Path, est: &Estimate) -> String {
    let mut o = String::new();
    let d = plan.dmm();
    let t = plan.table();
    let _ = writeln!(o, "plan {} — {}", path.display(), plan.name());
    let _ = writeln!(o, "hash {}", plan.hash());
    if plan.has_table() {
        let _ = writeln!(
            o,
            "table: {}{} on {} (max {} °/s, {} °/s², tolerance {} °/s for {:.1} s, timeout {:.0} s)",
            t.dialect.as_str(),
            if t.dialect == gyrocal_files::TableDialect::Aerosmith {
                " (experimental)"
            } else {
                ""
            },
            t.port,
            t.max_rate_dps,
            t.acceleration_dps2,
            t.rate_tolerance_dps,
            t.stability_window.as_secs_f64(),
            t.at_rate_timeout.as_secs_f64()
        );
    } else {
        let _ = writeln!(
            o,
            "table: none ([drift] table = \"none\": no table is opened)"
        );
    }
    let _ = writeln!(
        o,
        "multimeter: {} at {} baud, range {} V, NPLC {}, autozero {}, {} Hz: {:.1} ms per reading, acquisition {} -> {}",
        d.port,
        d.baud,
        d.range_v,
        d.nplc,
        if d.autozero { "on" } else { "off" },
        d.line_hz,
        est.reading_time.as_secs_f64() * 1e3,
        format!("{:?}", d.acquisition).to_lowercase(),
        est.acquisition
    );
    let _ = writeln!(o);
    let _ = writeln!(
        o,
        "{:>7} {:>7} {:>9} {:>8} {:>8} {:>8} {:>9} {:>10}",
        "step_no", "pass_no", "rate °/s", "samples", "ramp s", "dwell s", "acquire s", "at s"
    );
    // A run of identical steps (a drift record's segments, a plan repeated at one rate) is
    // shown by its first and last rows and one line between: 167 identical rows say nothing
    // the two rows and the count do not.
    let mut at = 0.0;
    let mut rows: Vec<(String, String)> = Vec::with_capacity(est.steps.len());
    for s in &est.steps {
        at += s.ramp.as_secs_f64() + s.settle.as_secs_f64() + s.acquire.as_secs_f64();
        let turns = match s.step.acquire {
            gyrocal_files::Acquire::Span { revolutions, .. } => format!(
                "  ({revolutions} turn{})",
                if revolutions == 1 { "" } else { "s" }
            ),
            gyrocal_files::Acquire::Samples(_) => String::new(),
        };
        // what the step does, without where it is in the schedule
        let what = format!(
            "{:>9} {:>8} {:>8.2} {:>8.2} {:>9.2}",
            s.step.rate_dps,
            s.samples,
            s.ramp.as_secs_f64(),
            s.settle.as_secs_f64(),
            s.acquire.as_secs_f64(),
        );
        let row = format!(
            "{:>7} {:>7} {what} {at:>10.1}{turns}",
            s.step.index + 1,
            s.step.pass + 1,
        );
        rows.push((what + &turns, row));
    }
    let mut i = 0;
    while i < rows.len() {
        let same = rows[i..].iter().take_while(|r| r.0 == rows[i].0).count();
        if same >= 4 {
            let _ = writeln!(o, "{}", rows[i].1);
            let _ = writeln!(
                o,
                "{:>9} steps {}–{} the same as step {}",
                "…",
                i + 2,
                i + same - 1,
                i + 1
            );
            let _ = writeln!(o, "{}", rows[i + same - 1].1);
        } else {
            for r in &rows[i..i + same] {
                let _ = writeln!(o, "{}", r.1);
            }
        }
        i += same;
    }
    let samples: u64 = est.steps.iter().map(|s| s.samples).sum();
    let _ = writeln!(o);
    let _ = writeln!(o, "{} steps, {} readings", est.steps.len(), samples);
    let _ = writeln!(o, "estimated duration {}", hms(est.total.as_secs_f64()));
    let _ = writeln!(
        o,
        "physical bound     {} (ramps at the acceleration limit + dwells + arming and reading time + unavoidable transfers)",
        hms(est.bound.as_secs_f64())
    );
    if let Some(k) = plan.kind_summary() {
        let _ = writeln!(o, "{}", k.line);
    }
    match plan.acceptance() {
        Some(a) => {
            let _ = writeln!(o, "acceptance ({} rule):", a.rule.as_str());
            for (q, l) in &a.limits {
                let bound =
                    |v: Option<f64>| v.map_or_else(|| "—".to_string(), gyrocal_fit::display::plain);
                // in words, then where the plan sets it (the key the operator edits)
                let _ = writeln!(
                    o,
                    "  {:<40} {} to {} {}{}  [acceptance.{}]",
                    q.title(),
                    bound(l.min),
                    bound(l.max),
                    q.unit(),
                    if l.marginal_min.is_some() || l.marginal_max.is_some() {
                        format!(
                            " (marginal outside {} to {})",
                            bound(l.marginal_min),
                            bound(l.marginal_max)
                        )
                    } else {
                        String::new()
                    },
                    q.name()
                );
            }
        }
        None => {
            let _ = writeln!(
                o,
                "acceptance: none (no [acceptance] in the plan: no verdict)"
            );
        }
    }
    if let Some(w) = plan.warmup() {
        let _ = writeln!(
            o,
            "warm-up: {}, {} s windows, up to {} (not in the estimate)",
            if gyrocal_files::steps::compile(plan, &[], false)
                .warmup_in_record
                .is_some()
            {
                "watched in the record's first segments"
            } else {
                "before the sweep, at 0 °/s"
            },
            w.window.as_secs_f64(),
            hms(w.max.as_secs_f64())
        );
    }
    o
}
