//! `gyrocal run PLAN`: the calibration run, on real instruments or on the simulated bench.
//!
//! The run directory is written as the run goes (see `gyrocal_files::rundir`); at the end the
//! data are fitted, `fit.json` and `report.html` written, and the elapsed time compared with
//! the physical bound.
//!
//! Stopping: the first SIGINT (Ctrl-C), SIGTERM, SIGHUP (a closed terminal, a dropped SSH
//! session) or SIGQUIT sends the table a controlled stop, and gyrocal then waits until the
//! table *reports* rest (measured rate within its stop tolerance, mode OFF) before it exits
//! (130, 143, 129 or 131: 128 + the signal's number), with the run `aborted` and the signal
//! named. The signals stay watched during that wait: a second one (any of the four) sends the
//! emergency stop (interlock open) at once. Any error does the same with `failed` (exit 1).
//! The last lines say where the table was left, and when rest could not be confirmed (a
//! silent table, a vanished port) they say so plainly: the operator must stop it by hand.
//! Everything printed here ignores write errors: after SIGHUP the terminal may be gone, and a
//! failed write must never cut the stop short. `--resume DIR` continues where a run stopped.

use std::io::{IsTerminal as _, Write as _};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use anyhow::Context as _;
use clap::Args;
use gyrocal_files::{Plan, RunDir, RunMeta, Status};
use gyrocal_link::Transport;
use gyrocal_run::{Event, Phase, RunSummary, SequencerOptions, StopRequest, TableRest};
use tokio::sync::{mpsc, watch};

use crate::BadInput;
use crate::cmd::check::{hms, load_plan};

/// Arguments of `gyrocal run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The test plan (TOML). Not needed with --resume: the run's own plan is in its manifest
    /// (given anyway, it must be the same plan; the keys that differ are named).
    #[arg(required_unless_present = "resume")]
    pub plan: Option<PathBuf>,
    /// Run against the in-process simulated bench built from the plan's `[simulation]`
    /// section, in virtual time (a full plan takes seconds).
    #[arg(long)]
    pub simulate: bool,
    /// With --simulate: pace the run's virtual clock at this many simulated seconds per real
    /// second instead of as fast as possible: the instruments, the gyro and the run's own
    /// waits (dwells, at-rate windows, timeouts) all keep the one clock, so a 10-minute plan
    /// at 20 takes 30 s and every figure on the run clock is exact (for watching the display,
    /// or rehearsing an interrupt).
    #[arg(long, value_name = "X", requires = "simulate")]
    pub sim_time_scale: Option<f64>,
    /// With --simulate: a fault to inject into the simulated bench, in `gyrocal sim`'s
    /// grammar (for example `dmm:garble@reading120`, `table:trip@demand4`); repeatable. For
    /// rehearsing what a run does when an instrument misbehaves.
    #[arg(long = "sim-fault", value_name = "SPEC", requires = "simulate")]
    pub sim_faults: Vec<String>,
    /// The gyro under test's serial number (recorded in the manifest and the report; not
    /// part of the plan; a resume refuses another serial).
    #[arg(long, value_name = "SERIAL")]
    pub dut_serial: Option<String>,
    /// The gyro under test's model.
    #[arg(long, value_name = "MODEL")]
    pub dut_model: Option<String>,
    /// Who runs the calibration.
    #[arg(long, value_name = "NAME")]
    pub operator: Option<String>,
    /// For whom.
    #[arg(long, value_name = "NAME")]
    pub customer: Option<String>,
    /// Ambient temperature as read in the lab, °C.
    #[arg(long, value_name = "CELSIUS")]
    pub ambient_c: Option<f64>,
    /// Relative humidity as read in the lab, %.
    #[arg(long, value_name = "PERCENT")]
    pub humidity_pct: Option<f64>,
    /// The station file: the lab, the bench, and per instrument its asset id, serial number,
    /// calibration certificate, due date and accuracy class (default: $GYROCAL_STATION, else
    /// the user's config directory's gyrocal/station.toml when it exists). Recorded in the
    /// manifest and on the report; a run refuses to start when a calibration is overdue.
    /// Without one, the report says "instruments not identified" (a simulated run uses the
    /// simulated bench's own records).
    #[arg(long, value_name = "FILE")]
    pub station: Option<PathBuf>,
    /// Start even when an instrument's calibration is overdue; recorded as a deviation.
    #[arg(long)]
    pub allow_expired: bool,
    /// The catalog that indexes the run: `sqlite:PATH` or `postgres://user@host/db`, or
    /// `off` (default: $GYROCAL_CATALOG, else the station file's `catalog`, else a SQLite
    /// file in the user's data directory). The run directory stays the source of truth: a
    /// catalog that fails never stops or slows the run (`gyrocal catalog import DIR`
    /// catches up).
    #[arg(long, value_name = "URL")]
    pub catalog: Option<String>,
    /// Start a live view of the run in this process (read-only, over the run's own root,
    /// as `gyrocal serve`): ADDR defaults to 127.0.0.1 on any free port; the run's page is
    /// printed before the first step. Off loopback it needs $GYROCAL_SERVE_TOKEN. The view
    /// only reads the run's files: it costs the run nothing.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = live::SERVE_DEFAULT)]
    pub serve: Option<String>,
    /// Print exactly one JSON document on stdout at the end (status, exit code, where the
    /// table was left, steps, timing, the fit's headline, the run directory, the resume
    /// command); the human text goes to stderr.
    #[arg(long)]
    pub json: bool,
    /// The run directory to create (default: runs/<plan>-<UTC time>).
    #[arg(short = 'o', long, value_name = "DIR", conflicts_with = "resume")]
    pub out: Option<PathBuf>,
    /// Continue the interrupted run in DIR (the plan must be the same).
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
    /// The multimeter's port, overriding the plan (a serial device or tcp://HOST:PORT).
    #[arg(long, value_name = "PORT")]
    pub dmm_port: Option<String>,
    /// The rate table's port, overriding the plan (a serial device or tcp://HOST:PORT).
    #[arg(long, value_name = "PORT")]
    pub table_port: Option<String>,
    /// The thermal chamber's port, overriding the plan's `[chamber] port` (a serial device for
    /// Modbus RTU or the Espec's text, tcp://HOST:PORT for Modbus TCP).
    #[arg(long, value_name = "PORT")]
    pub chamber_port: Option<String>,
    /// Do not write report.html at the end.
    #[arg(long)]
    pub no_report: bool,
    /// Exit with 3 when a complete run's acceptance verdict is LEVEL or worse (pass <
    /// marginal < indeterminate < fail; LEVEL defaults to fail), or when it has no verdict (no
    /// [acceptance] in the plan): for CI and scripts that must fail on a rejected gyro. The
    /// run, its files and the catalog are the same either way.
    #[arg(long, value_name = "LEVEL", num_args = 0..=1, default_missing_value = "fail")]
    pub fail_on_verdict: Option<VerdictLevel>,
}

/// The verdict at or beyond which `--fail-on-verdict` exits 3.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum VerdictLevel {
    /// Inside the limits but outside the marginal band, or worse.
    Marginal,
    /// Cannot be decided, or worse.
    Indeterminate,
    /// Outside the limits.
    Fail,
}

impl VerdictLevel {
    fn verdict(self) -> gyrocal_fit::acceptance::Verdict {
        use gyrocal_fit::acceptance::Verdict;
        match self {
            VerdictLevel::Marginal => Verdict::Marginal,
            VerdictLevel::Indeterminate => Verdict::Indeterminate,
            VerdictLevel::Fail => Verdict::Fail,
        }
    }
}

/// The exit code of a complete run whose verdict `--fail-on-verdict` refuses.
pub const EXIT_VERDICT: u8 = 3;

/// Writes a line to stderr, ignoring errors (the terminal may be gone after SIGHUP).
macro_rules! say {
    ($($t:tt)*) => {{
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

/// Writes a line to stdout, ignoring errors (a closed pipe must not end the run's ending).
macro_rules! out {
    ($($t:tt)*) => {{
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

// Split by concern (the macros above are visible in each):
mod clock;
mod ending;
mod execute;
mod live;
mod progress;
mod records;

use clock::*;
use ending::*;
use execute::*;
use progress::*;
use records::*;

/// A signal that stops a run, with its conventional exit code (128 + its number).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StopSignal {
    /// `SIGINT`, `SIGTERM`, `SIGHUP` or `SIGQUIT`.
    pub name: &'static str,
    /// 128 + the signal's number.
    pub exit_code: u8,
}

/// The signals that stop a run: the first is a controlled stop, any further one an emergency
/// stop.
pub const STOP_SIGNALS: [StopSignal; 4] = [
    StopSignal {
        name: "SIGINT",
        exit_code: 130,
    },
    StopSignal {
        name: "SIGTERM",
        exit_code: 143,
    },
    StopSignal {
        name: "SIGHUP",
        exit_code: 129,
    },
    StopSignal {
        name: "SIGQUIT",
        exit_code: 131,
    },
];

/// Exit code of a run aborted by something other than a signal.
pub const EXIT_ABORTED: u8 = 130;

/// Runs `gyrocal run`; returns the process exit code.
pub fn run(args: &RunArgs) -> anyhow::Result<u8> {
    let (mut plan, plan_path) = match (&args.plan, &args.resume) {
        (Some(path), _) => (load_plan(path)?, path.clone()),
        (None, Some(dir)) => {
            let plan = gyrocal_files::rundir::run_plan(dir)
                .map_err(|e| crate::run_dir_error(e, Some("--resume")))?;
            (plan, dir.join(gyrocal_files::rundir::MANIFEST_JSON))
        }
        (None, None) => return Err(BadInput("a plan (or --resume DIR) is needed".into()).into()),
    };
    crate::cmd::check::override_ports(
        &mut plan,
        args.dmm_port.as_deref(),
        args.table_port.as_deref(),
    )?;
    // the chamber's too, into the plan the manifest records: a run killed before its ending
    // (which repeats --chamber-port) is resumed by `--resume DIR` at the same chamber
    if let Some(p) = &args.chamber_port {
        let spec = p
            .parse::<gyrocal_link::PortSpec>()
            .map_err(|e| BadInput(format!("--chamber-port {p}: {e}")))?;
        plan.set_chamber_port(spec);
    }
    if let Some(x) = args.sim_time_scale
        && !(x.is_finite() && x > 0.0)
    {
        return Err(BadInput(format!("--sim-time-scale must be > 0 (got {x})")).into());
    }
    let dut = dut_for_run(args, &plan);
    if let Some(dir) = &args.resume {
        check_resume_mode(dir, args.simulate)?;
        check_resume_dut(dir, dut.as_ref().and_then(|d| d.serial.as_deref()))?;
    }
    for (key, v, range) in [
        ("--ambient-c", args.ambient_c, -50.0..=100.0),
        ("--humidity-pct", args.humidity_pct, 0.0..=100.0),
    ] {
        if let Some(v) = v
            && !range.contains(&v)
        {
            return Err(BadInput(format!(
                "{key} {v} is outside {}..={}",
                range.start(),
                range.end()
            ))
            .into());
        }
    }
    if let Some(text) = &args.serve {
        // a bad address is bad input before anything is opened
        live::serve_addr(text)?;
    }
    // the station before any instrument is touched: an overdue calibration refuses the run
    let (station, deviations) = station_for_run(args, &plan, plan.simulation().seed)?;
    let catalog = catalog_url(args, station.as_ref())?;
    let records = Records {
        dut,
        station,
        deviations,
        catalog,
    };
    // what `check` warns about, said again before the instruments move
    for w in gyrocal_analysis::plan_warnings(&plan, &plan_path) {
        say!("gyrocal: warning: {w}");
    }
    let mut faults = Vec::with_capacity(args.sim_faults.len());
    for text in &args.sim_faults {
        let spec: gyrocal_sim::faults::FaultSpec =
            text.parse()
                .map_err(|e: gyrocal_sim::faults::FaultSpecError| {
                    BadInput(format!(
                        "--sim-fault: {e} (the grammar is in `gyrocal sim --help`)"
                    ))
                })?;
        faults.push(spec);
    }
    // a simulated bench always runs on the virtual clock (paced with --sim-time-scale)
    let virtual_time = args.simulate;
    let mut rt = if virtual_time {
        let mut b = tokio::runtime::Builder::new_current_thread();
        b.start_paused(true);
        b
    } else {
        tokio::runtime::Builder::new_multi_thread()
    };
    let rt = rt
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let (dir, summary, run, signal, bench) = rt.block_on(execute(args, plan, &faults, records))?;
    let mut doc = serde_json::json!({ "simulated_bench": bench });
    let code = finish(args, &dir, &summary, run, signal, &mut doc);
    if args.json {
        // one document on stdout, whatever happened after the sequencer
        if let Err(e) = &code {
            doc["error"] = serde_json::json!(format!("{e:#}"));
        }
        out!("{doc:#}");
    }
    code
}
