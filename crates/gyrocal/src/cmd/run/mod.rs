//! `gyrocal run PLAN`: the calibration run, on real instruments or on the simulated bench.
//!
//! The run directory is written as the run goes (see `gyrocal_run::rundir`); at the end the
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
use gyrocal_link::Transport;
use gyrocal_run::{
    Event, Phase, Plan, Port, RunDir, RunMeta, RunSummary, Sequencer, SequencerOptions, Status,
    StopRequest, TableRest, fit_run,
};
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
    /// Do not write report.html at the end.
    #[arg(long)]
    pub no_report: bool,
}

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
            let plan = gyrocal_run::rundir::run_plan(dir)
                .map_err(|e| crate::run_dir_error(e, Some("--resume")))?;
            (plan, dir.join(gyrocal_run::rundir::MANIFEST_JSON))
        }
        (None, None) => return Err(BadInput("a plan (or --resume DIR) is needed".into()).into()),
    };
    crate::cmd::check::override_ports(
        &mut plan,
        args.dmm_port.as_deref(),
        args.table_port.as_deref(),
    )?;
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
    for w in crate::cmd::check::model_warnings(&plan, &plan_path) {
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

/// Deviations known before the run directory exists: (kind, text).
type PendingDeviations = Vec<(String, String)>;

/// What a run records about the gyro, the station and the departures known before it starts.
struct Records {
    dut: Option<gyrocal_run::Dut>,
    station: Option<gyrocal_run::station::Station>,
    /// (kind, text) of each deviation to record when the run directory is open.
    deviations: PendingDeviations,
    /// Where the run is indexed (`None`: not at all).
    catalog: Option<gyrocal_catalog::CatalogUrl>,
}

/// The catalog writer of this process's run and the run directory it indexes: set when the
/// run directory is open, told of every step by the progress view, closed at the end. One
/// run per process, so one slot.
static CATALOG: std::sync::Mutex<Option<(gyrocal_catalog::CatalogWriter, PathBuf)>> =
    std::sync::Mutex::new(None);

/// Tells the catalog writer (if any) about the run; never blocks on the catalog.
fn catalog_note(f: impl FnOnce(&gyrocal_catalog::CatalogWriter, &Path)) {
    if let Ok(slot) = CATALOG.lock()
        && let Some((w, dir)) = slot.as_ref()
    {
        f(w, dir);
    }
}

/// The catalog for this run: `--catalog`, `$GYROCAL_CATALOG`, the station's `catalog`, the
/// default SQLite file; `off` (or `none`) in the flag or the variable turns it off. A bad
/// `--catalog` is bad input; any other catalog trouble is a warning (the run goes on).
fn catalog_url(
    args: &RunArgs,
    station: Option<&gyrocal_run::station::Station>,
) -> anyhow::Result<Option<gyrocal_catalog::CatalogUrl>> {
    let off = |s: &str| matches!(s.trim(), "off" | "none");
    if let Some(flag) = &args.catalog {
        if off(flag) {
            return Ok(None);
        }
        return gyrocal_catalog::CatalogUrl::parse(flag)
            .map(Some)
            .map_err(|e| BadInput(format!("--catalog: {e}")).into());
    }
    if std::env::var(gyrocal_catalog::CATALOG_ENV).is_ok_and(|v| off(&v)) {
        return Ok(None);
    }
    match gyrocal_catalog::resolve(None, station.and_then(|s| s.catalog.as_deref())) {
        Ok(url) => Ok(Some(url)),
        Err(e) => {
            say!(
                "gyrocal: warning: catalog: {e}: the run is not indexed (`gyrocal catalog import DIR` later)"
            );
            Ok(None)
        }
    }
}

/// The gyro under test: the plan's `[dut]`, overridden by `--dut-serial`/`--dut-model`. A new
/// simulated run without a serial gets the simulated gyro's (`SIM-GYRO-<seed>`), so its
/// certificate is complete; a resume keeps what the run recorded.
fn dut_for_run(args: &RunArgs, plan: &Plan) -> Option<gyrocal_run::Dut> {
    let from_plan = plan.dut().cloned().unwrap_or_default();
    let mut dut = from_plan.overridden_by(gyrocal_run::Dut {
        serial: args.dut_serial.clone(),
        model: args.dut_model.clone(),
        ..gyrocal_run::Dut::default()
    });
    if args.simulate && args.resume.is_none() && dut.serial.is_none() {
        dut.serial = Some(format!("SIM-GYRO-{}", plan.simulation().seed));
        dut.model
            .get_or_insert_with(|| "simulated HRG (gyrocal)".to_string());
    }
    (!dut.is_empty()).then_some(dut)
}

/// The station (`--station`, `$GYROCAL_STATION`, the default file; a simulated run without
/// one uses the simulated bench's records) and the deviation an overdue calibration brings
/// with `--allow-expired`. Without `--allow-expired` an overdue calibration is bad input:
/// nothing is opened or created.
fn station_for_run(
    args: &RunArgs,
    plan: &Plan,
    sim_seed: u64,
) -> anyhow::Result<(Option<gyrocal_run::station::Station>, PendingDeviations)> {
    use gyrocal_run::station::Station;
    let today = jiff::Zoned::now().date();
    let station = match Station::resolve(args.station.as_deref())
        .map_err(|e| BadInput(format!("station: {e}")))?
    {
        Some((path, s)) => {
            say!("station: {} ({})", s.id, path.display());
            for line in crate::cmd::check::station_warnings(&s, &path, plan.has_table()) {
                say!("gyrocal: warning: {line}");
            }
            Some(s)
        }
        None if args.simulate => Some(Station::simulated(sim_seed, today)),
        None => None,
    };
    let mut deviations = Vec::new();
    if let Some(s) = &station {
        // a plan without a table does not use the station's table: its calibration is moot
        let overdue: Vec<_> = s
            .overdue(today)
            .into_iter()
            .filter(|o| plan.has_table() || o.role != "table")
            .collect();
        if !overdue.is_empty() {
            let list = overdue
                .iter()
                .map(|o| {
                    format!(
                        "the {} {} was due for calibration on {}",
                        o.role, o.asset_id, o.due
                    )
                })
                .collect::<Vec<_>>()
                .join("; ");
            if !args.allow_expired {
                return Err(BadInput(format!(
                    "station {}: {list} (today is {today}): calibrate it, or start with \
                     --allow-expired, which the report records as a deviation",
                    s.id
                ))
                .into());
            }
            say!(
                "gyrocal: warning: {list}: started with --allow-expired (recorded as a deviation)"
            );
            deviations.push((
                "expired-calibration".to_string(),
                format!("{list}; the run was started with --allow-expired on {today}"),
            ));
        }
    }
    Ok((station, deviations))
}

fn open_run_dir(
    args: &RunArgs,
    plan: &Plan,
    records: Records,
) -> anyhow::Result<(PathBuf, RunDir)> {
    let (dir, mut run) = open_run_dir_inner(args, plan, records.dut, records.station)?;
    for (kind, text) in &records.deviations {
        run.add_deviation(kind, text)
            .map_err(|e| anyhow::anyhow!("{}: recording a deviation: {e}", dir.display()))?;
    }
    if let Some(url) = records.catalog {
        tracing::info!(catalog = %url, "indexing the run");
        let writer = gyrocal_catalog::CatalogWriter::spawn(url);
        writer.register(&dir);
        if let Ok(mut slot) = CATALOG.lock() {
            *slot = Some((writer, dir.clone()));
        }
    }
    Ok((dir, run))
}

fn open_run_dir_inner(
    args: &RunArgs,
    plan: &Plan,
    dut: Option<gyrocal_run::Dut>,
    station: Option<gyrocal_run::station::Station>,
) -> anyhow::Result<(PathBuf, RunDir)> {
    let virtual_time = args.simulate;
    // the environment as entered, else the station's usual conditions
    let context = gyrocal_run::RunContext {
        operator: args.operator.clone(),
        customer: args.customer.clone(),
        ambient_c: args
            .ambient_c
            .or_else(|| station.as_ref().and_then(|s| s.ambient_c)),
        humidity_pct: args
            .humidity_pct
            .or_else(|| station.as_ref().and_then(|s| s.humidity_pct)),
    };
    let meta = RunMeta {
        gyrocal_version: env!("CARGO_PKG_VERSION").into(),
        simulated: args.simulate,
        virtual_time,
        dut,
        station,
        context: (context != gyrocal_run::RunContext::default()).then_some(context),
        ..RunMeta::default()
    };
    // A directory whose creation was interrupted holds no data: the run starts in it.
    if let Some(dir) = &args.resume
        && RunDir::is_half_created(dir).unwrap_or(false)
    {
        eprintln!(
            "{}: the run never started (no manifest.json); starting it in this directory",
            dir.display()
        );
        let run = RunDir::create(dir, plan, meta)
            .map_err(|e| crate::run_dir_error(e, Some("--resume")))?;
        attach_log(dir);
        return Ok((dir.clone(), run));
    }
    if let Some(dir) = &args.resume {
        let mut run = RunDir::open_for_resume(dir, plan)
            .map_err(|e| crate::run_dir_error(e, Some("--resume")))?;
        // the record keeps the station the run started on; a resume on other instruments is
        // a departure from it, recorded so the certificate says so
        if let Some(text) = station_change(run.manifest().station.as_ref(), meta.station.as_ref()) {
            say!("gyrocal: warning: {text} (recorded as a deviation)");
            run.add_deviation("station-changed", &text)
                .map_err(|e| crate::run_dir_error(e, Some("--resume")))?;
        }
        if virtual_time {
            run.set_virtual_time()
                .map_err(|e| crate::run_dir_error(e, Some("--resume")))?;
        }
        let done = run.done_steps().len();
        say!(
            "resuming {}: {done} of {} steps done, {} to go",
            dir.display(),
            run.schedule().len(),
            run.remaining_steps().len()
        );
        attach_log(dir);
        return Ok((dir.clone(), run));
    }
    let dir = match &args.out {
        Some(d) => d.clone(),
        None => default_dir(args.plan.as_deref().unwrap_or(Path::new("run"))),
    };
    let run = RunDir::create(&dir, plan, meta).map_err(|e| crate::run_dir_error(e, None))?;
    attach_log(&dir);
    Ok((dir, run))
}

/// How a station reads in a deviation: its id and its instruments' asset ids and serials.
fn station_words(s: &gyrocal_run::station::Station) -> String {
    let instruments = s
        .instruments()
        .iter()
        .map(|(role, r)| format!("{role} {} (serial {})", r.asset_id, r.serial))
        .collect::<Vec<_>>()
        .join(", ");
    if instruments.is_empty() {
        format!("station {}", s.id)
    } else {
        format!("station {} with {instruments}", s.id)
    }
}

/// The deviation a resume on another station is, or `None` when the station (its id, and its
/// instruments' models, asset ids, serials and certificates; not the dates, which a simulated
/// station takes from the day) is the one the run started on.
fn station_change(
    started: Option<&gyrocal_run::station::Station>,
    now: Option<&gyrocal_run::station::Station>,
) -> Option<String> {
    let key = |s: &gyrocal_run::station::Station| {
        let mut k = vec![s.id.clone()];
        for (role, r) in s.instruments() {
            k.extend([
                role.to_string(),
                r.model.clone(),
                r.asset_id.clone(),
                r.serial.clone(),
                r.certificate.clone(),
            ]);
        }
        k
    };
    match (started, now) {
        (None, None) => None,
        (Some(a), Some(b)) if key(a) == key(b) => None,
        (Some(a), Some(b)) => Some(format!(
            "the run started on {} and was resumed on {}",
            station_words(a),
            station_words(b)
        )),
        (None, Some(b)) => Some(format!(
            "the run started without a station file and was resumed on {}",
            station_words(b)
        )),
        (Some(a), None) => Some(format!(
            "the run started on {} and was resumed without a station file: the instruments of the resumed steps are not identified",
            station_words(a)
        )),
    }
}

/// Refuses to continue a run with another gyro: `--dut-serial` on a resume must be the serial
/// the run recorded (a calibration is of one gyro). Reads only the manifest.
fn check_resume_dut(dir: &Path, serial: Option<&str>) -> anyhow::Result<()> {
    let Some(serial) = serial else {
        return Ok(());
    };
    let path = dir.join(gyrocal_run::rundir::MANIFEST_JSON);
    let Ok(bytes) =
        gyrocal_run::rundir::read_capped(&path, gyrocal_run::rundir::MAX_MANIFEST_BYTES)
    else {
        return Ok(()); // the resume names the missing or unreadable manifest itself
    };
    let recorded = serde_json::from_slice::<serde_json::Value>(&bytes)
        .ok()
        .and_then(|m| m["dut"]["serial"].as_str().map(str::to_string));
    match recorded {
        Some(r) if r != serial => Err(BadInput(format!(
            "--resume: {} is the calibration of gyro serial {r}; --dut-serial {serial} is another gyro: start a new run for it",
            dir.display()
        ))
        .into()),
        None => Err(BadInput(format!(
            "--resume: {} names no gyro; --dut-serial cannot be added to a run part-way",
            dir.display()
        ))
        .into()),
        _ => Ok(()),
    }
}

/// Refuses to continue a simulated run on the instruments or the reverse, before anything is
/// opened or changed: it would mix simulated and measured data in one calibration. Reads only
/// the manifest's `simulated` flag (the rest is checked by the resume itself).
fn check_resume_mode(dir: &Path, simulate: bool) -> anyhow::Result<()> {
    let path = dir.join(gyrocal_run::rundir::MANIFEST_JSON);
    let Ok(bytes) =
        gyrocal_run::rundir::read_capped(&path, gyrocal_run::rundir::MAX_MANIFEST_BYTES)
    else {
        return Ok(()); // the resume names the missing, unreadable or oversized manifest itself
    };
    let manifest = serde_json::from_slice::<serde_json::Value>(&bytes).ok();
    let simulated = manifest
        .as_ref()
        .and_then(|m| m.get("simulated").and_then(serde_json::Value::as_bool));
    // a run against `gyrocal sim` (marked by its instruments' identities) goes on against the
    // instruments' ports; the sequencer checks again who answers there
    let by_instruments = manifest
        .as_ref()
        .is_some_and(|m| m.get("simulated_by").is_some_and(|v| !v.is_null()));
    if let Some(simulated) = simulated
        && simulated != simulate
        && !(simulated && by_instruments)
    {
        let (was, now) = if simulate {
            ("on the instruments", "--simulate")
        } else {
            ("on the simulated bench", "the instruments")
        };
        return Err(BadInput(format!(
            "--resume: {} was run {was}; continuing it with {now} would mix simulated and \
             measured data in one calibration",
            dir.display()
        ))
        .into());
    }
    Ok(())
}

/// The run's log goes to `DIR/run.log` too (appended on a resume).
fn attach_log(dir: &Path) {
    let path = dir.join("run.log");
    if let Err(e) = crate::runlog::attach(&path) {
        say!("gyrocal: warning: no run log at {}: {e}", path.display());
    }
}

fn default_dir(plan: &Path) -> PathBuf {
    let stem = plan.file_stem().and_then(|s| s.to_str()).unwrap_or("run");
    let now = gyrocal_run::rfc3339_utc(std::time::SystemTime::now()).replace(':', "");
    PathBuf::from("runs").join(format!("{stem}-{now}"))
}

/// Opens the instruments' links (or builds the simulated bench), then the run directory (so a
/// port that does not open leaves no run directory behind), and runs the sequencer.
async fn execute(
    args: &RunArgs,
    plan: Plan,
    faults: &[gyrocal_sim::faults::FaultSpec],
    records: Records,
) -> anyhow::Result<(
    PathBuf,
    RunSummary,
    RunDir,
    Option<StopSignal>,
    Option<serde_json::Value>,
)> {
    if args.simulate {
        let cfg = gyrocal_sim::from_plan::bench_config(&plan);
        let has_table = plan.has_table();
        if let Some(x) = args.sim_time_scale {
            tokio::spawn(pace(x));
        }
        let time_scale = cfg.time_scale;
        let bench = gyrocal_sim::bench::Bench::spawn(cfg);
        let mut schedule = gyrocal_sim::faults::schedule(faults, &bench.handle, time_scale);
        let (dir, run) = open_run_dir(args, &plan, records)?;
        let (summary, run, signal) = match &plan.dmm().port {
            // the plan reaches the meter over GPIB: the bench put a simulated Prologix
            // controller in front of it, and the real Prologix transport talks to that
            Port::Gpib(spec) => {
                let options = match gyrocal_link::parse_port(spec) {
                    Ok(gyrocal_link::PortSpec::PrologixSerial { options, .. })
                    | Ok(gyrocal_link::PortSpec::PrologixTcp { options, .. }) => options,
                    _ => gyrocal_link::PrologixOptions::default(),
                };
                let dmm = gyrocal_link::PrologixTransport::open(bench.dmm, options)
                    .await
                    .context("opening the simulated Prologix controller")?;
                sequence(plan, dmm, Some(bench.table), run).await?
            }
            // a Truevolt on its LAN socket: device clear reconnects to the simulated meter
            _ if plan.dmm().model.is_truevolt() => {
                let Some(lan) = bench.handle.lan.clone() else {
                    anyhow::bail!("the simulated bench has no LAN meter for a Truevolt plan");
                };
                let dmm = gyrocal_link::SocketTransport::new(bench.dmm.boxed(), lan.connector());
                sequence(plan, dmm, Some(bench.table), run).await?
            }
            _ => sequence(plan, bench.dmm, Some(bench.table), run).await?,
        };
        // let the simulator take the last commands before it is dropped
        tokio::time::sleep(Duration::from_millis(50)).await;
        for f in schedule.status(&bench.handle) {
            say!(
                "simulated fault {}: {}",
                f.spec,
                if f.fired { "fired" } else { "did not fire" }
            );
        }
        schedule.stop();
        let t = &bench.handle.table;
        // what the simulated table itself says (the run's own account came from the driver)
        if has_table {
            say!(
                "simulated table at the end: mode {:?}, demand {:+} °/s, {}",
                t.mode(),
                t.demanded_rate(),
                if t.is_stopped() {
                    "at rest"
                } else {
                    "NOT at rest"
                }
            );
        }
        let state = serde_json::json!({
            "table": {
                "mode": format!("{:?}", t.mode()),
                "demanded_dps": t.demanded_rate(),
                "stopped": t.is_stopped(),
                "interlock_closed": t.interlock_closed(),
            }
        });
        Ok((dir, summary, run, signal, Some(state)))
    } else {
        // Every instrument must answer before anything is created on disk.
        let found = crate::cmd::probe::probe(&plan).await?;
        say!(
            "probe: both instruments answer (the table in mode {} at {:+.4} °/s)",
            found.table_mode,
            found.table_rate_dps
        );
        let d = plan.dmm();
        let dmm = gyrocal_link::open(
            &d.port.to_string(),
            &crate::cmd::probe::dmm_link_options(&plan),
        )
        .await
        .with_context(|| format!("opening the multimeter at {}", d.port))?;
        let t = plan.table();
        let table = if plan.has_table() {
            Some(
                gyrocal_link::open(
                    &t.port.to_string(),
                    &crate::cmd::probe::table_link_options(&plan),
                )
                .await
                .with_context(|| format!("opening the rate table at {}", t.port))?,
            )
        } else {
            None
        };
        let (dir, run) = open_run_dir(args, &plan, records)?;
        let (summary, run, signal) = sequence(plan, dmm, table, run).await?;
        Ok((dir, summary, run, signal, None))
    }
}

/// Paces the paused (virtual) clock at `x` simulated seconds per real second: a real sleep
/// on the blocking pool (while it runs, tokio does not auto-advance the paused clock), then
/// the clock advanced by `x` times as much. Everything on the clock (the simulated
/// instruments, the sequencer's waits) keeps its order and its exact virtual timings.
async fn pace(x: f64) {
    // 1 ms of real time per step: at x = 20 a timer fires at most 20 ms late on the run
    // clock (the run's ratio to the bound shows it: 1.0181 with 5 ms ticks, see the tests)
    let tick = Duration::from_millis(1);
    let step = tick.mul_f64(x);
    loop {
        if tokio::task::spawn_blocking(move || std::thread::sleep(tick))
            .await
            .is_err()
        {
            return;
        }
        tokio::time::advance(step).await;
    }
}

/// The instruments the plan names, built on their links by [`crate::instruments`] (the one
/// place that knows the drivers), then the same generic sequence for every combination.
async fn sequence<D, T>(
    plan: Plan,
    dmm_link: D,
    table_link: Option<T>,
    run: RunDir,
) -> anyhow::Result<(RunSummary, RunDir, Option<StopSignal>)>
where
    D: Transport + 'static,
    T: Transport + 'static,
{
    let p = plan.clone();
    crate::instruments::with_instruments(&p, dmm_link, table_link, Sequence { plan, run }).await
}

/// The run's job once its instruments are built.
struct Sequence {
    plan: Plan,
    run: RunDir,
}

impl crate::instruments::WithInstruments for Sequence {
    type Output = anyhow::Result<(RunSummary, RunDir, Option<StopSignal>)>;

    async fn call<M, T>(self, dmm: M, table: T) -> Self::Output
    where
        M: gyrocal_meter::Multimeter + 'static,
        T: gyrocal_table::RateTable + 'static,
    {
        sequence_with(self.plan, dmm, table, self.run).await
    }
}

/// Runs the sequencer with signals watched and progress shown, whatever the instruments.
async fn sequence_with<M, T>(
    plan: Plan,
    dmm: M,
    table: T,
    run: RunDir,
) -> anyhow::Result<(RunSummary, RunDir, Option<StopSignal>)>
where
    M: gyrocal_meter::Multimeter + 'static,
    T: gyrocal_table::RateTable + 'static,
{
    let (tx, rx) = mpsc::unbounded_channel();
    let mut seq =
        Sequencer::new(plan, dmm, table, run, SequencerOptions::default()).with_events(tx);
    let (stop_tx, stop_rx) = watch::channel(StopRequest::None);
    let stop_handle = seq.stop_handle();
    let first_signal = Arc::new(OnceLock::new());
    // Signals are watched until the sequencer has returned, and it returns only once the
    // table is at rest (or that could not be confirmed): a second signal during the
    // deceleration is the emergency stop.
    let signals = tokio::spawn(watch_signals(
        stop_tx,
        stop_handle.clone(),
        first_signal.clone(),
    ));
    let display = tokio::spawn(show_progress(rx));
    // The sequencer catches a panic in its steps itself (and still brings the table to
    // rest); running it as a task of its own is the second line: a panic anywhere else in
    // it comes back here, with the runtime still alive to stop the table.
    let task = tokio::spawn(async move {
        let summary = seq.run(stop_rx).await;
        (summary, seq.into_run_dir())
    });
    let result = task.await;
    signals.abort();
    let _ = display.await;
    let signal = first_signal.get().copied();
    match result {
        Ok((summary, run)) => Ok((summary, run, signal)),
        Err(e) => {
            say!("gyrocal: internal error in the sequencer ({e}); stopping the table");
            if let Err(e) = stop_handle.stop().await {
                say!("gyrocal: controlled stop failed: {e}");
            }
            if let Err(e) = stop_handle.emergency_stop().await {
                say!("gyrocal: emergency stop failed: {e}");
            }
            anyhow::bail!(
                "the sequencer stopped unexpectedly ({e}); a stop and an emergency stop were \
                 sent, but the table could NOT be confirmed at rest: check it and stop it by \
                 hand if it turns. The run directory is resumable (its manifest still says \
                 running)"
            )
        }
    }
}

/// The first of SIGINT, SIGTERM, SIGHUP, SIGQUIT: controlled stop (the sequencer then waits
/// for rest). Any further one: emergency stop at once, from here (the sequencer may be
/// waiting on the table's link), and the sequencer is told too.
async fn watch_signals(
    stop: watch::Sender<StopRequest>,
    table: gyrocal_table::StopHandle,
    first: Arc<OnceLock<StopSignal>>,
) {
    let (tx, mut rx) = mpsc::unbounded_channel::<StopSignal>();
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let kinds = [
            SignalKind::interrupt(),
            SignalKind::terminate(),
            SignalKind::hangup(),
            SignalKind::quit(),
        ];
        for (kind, sig) in kinds.into_iter().zip(STOP_SIGNALS) {
            match signal(kind) {
                Ok(mut stream) => {
                    let tx = tx.clone();
                    tokio::spawn(async move {
                        while stream.recv().await.is_some() {
                            if tx.send(sig).is_err() {
                                return;
                            }
                        }
                    });
                }
                Err(e) => tracing::warn!(error = %e, "cannot watch {}", sig.name),
            }
        }
    }
    #[cfg(not(unix))]
    {
        let tx = tx.clone();
        tokio::spawn(async move {
            while tokio::signal::ctrl_c().await.is_ok() {
                if tx.send(STOP_SIGNALS[0]).is_err() {
                    return;
                }
            }
        });
    }
    drop(tx);
    while let Some(sig) = rx.recv().await {
        if first.set(sig).is_ok() {
            say!(
                "\ngyrocal: {}: controlled stop of the table; gyrocal exits once the table is at \
                 rest; interrupt again for an emergency stop",
                sig.name
            );
            let _ = stop.send(StopRequest::Controlled(sig.name));
        } else {
            say!("\ngyrocal: {}: EMERGENCY STOP (interlock open)", sig.name);
            let _ = stop.send(StopRequest::Emergency(sig.name));
            if let Err(e) = table.emergency_stop().await {
                say!("gyrocal: emergency stop failed: {e}: STOP THE TABLE BY HAND");
            }
        }
    }
}

/// An indicatif display on a terminal; plain lines otherwise.
async fn show_progress(mut rx: mpsc::UnboundedReceiver<Event>) {
    // the bar draws on stderr; with either stream redirected (a log file, CI), plain lines
    let tty = std::io::stdout().is_terminal() && std::io::stderr().is_terminal();
    let mut view = Progress::new(tty);
    // the ETA and the bar count down between events too
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            e = rx.recv() => match e {
                Some(e) => {
                    if matches!(e, Event::StepDone(_)) {
                        catalog_note(|w, dir| w.step_done(dir));
                    }
                    view.event(e)
                }
                None => break,
            },
            _ = tick.tick(), if tty => view.redraw(),
        }
    }
    view.bar.finish_and_clear();
}

/// The live view of a run: one line per step and event (or a bar on a terminal, which fits
/// 80 columns: the message is cut, not wrapped), a time-based bar and ETA from the
/// instruments' timing models that move within a step, the phase, and the step's latest
/// reading with its running mean and σ.
struct Progress {
    tty: bool,
    bar: indicatif::ProgressBar,
    /// The session's estimated duration (the bar's length, ms).
    estimate: Duration,
    /// The current step: its label, when it started, its `remaining` and `after`.
    step: Option<(String, tokio::time::Instant, Duration, Duration)>,
    /// Steps started and not yet recorded (a memory-mode step is recorded during the next
    /// ramp), with the readings received so far: on a stop, these are discarded.
    open: Vec<(usize, String, usize)>,
    phase: String,
    /// The warm-up's end was said.
    warmup_reported: bool,
}

impl Progress {
    fn new(tty: bool) -> Self {
        let bar = indicatif::ProgressBar::hidden();
        if tty {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{prefix:.bold} {elapsed_precise} [{bar:16}] {wide_msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
        }
        Progress {
            tty,
            bar,
            estimate: Duration::ZERO,
            step: None,
            open: Vec::new(),
            phase: String::new(),
            warmup_reported: false,
        }
    }

    /// The time left in the run by the clock: the step's estimate counted down, never below
    /// what the later steps take.
    fn remaining(&self) -> Option<Duration> {
        let (_, started, remaining, after) = self.step.as_ref()?;
        Some(remaining.saturating_sub(started.elapsed()).max(*after))
    }

    fn redraw(&self) {
        let eta = match self.remaining() {
            Some(r) => {
                let done = self.estimate.saturating_sub(r);
                self.bar.set_position(done.as_millis() as u64);
                format!("ETA {}", short_hms(r.as_secs_f64()))
            }
            None => String::new(),
        };
        self.bar.set_message(format!("{eta} · {}", self.phase));
    }

    fn line(&self, text: String) {
        line(self.tty, &self.bar, text);
    }

    fn event(&mut self, e: Event) {
        match e {
            Event::Connected { dmm, table } => {
                self.line(format!("multimeter: {dmm}\nrate table: {table}"))
            }
            Event::Planned {
                steps,
                done,
                estimate,
                acquisition,
            } => {
                self.estimate = estimate;
                self.bar.set_length(estimate.as_millis().max(1) as u64);
                self.line(format!(
                    "{steps} steps to run ({done} already done), acquisition {acquisition}, estimated {}",
                    hms(estimate.as_secs_f64())
                ));
            }
            Event::StepStarted {
                step,
                number,
                of,
                remaining,
                after,
                ..
            } => {
                let label = format!("step {number}/{of} {:+} °/s", step.rate_dps);
                self.step = Some((label.clone(), tokio::time::Instant::now(), remaining, after));
                self.open.push((step.index, label.clone(), 0));
                self.bar.set_prefix(label.clone());
                self.phase = "ramping".into();
                if !self.tty {
                    say!("{label} (ETA {})", hms(remaining.as_secs_f64()));
                }
                self.redraw();
            }
            Event::Settle(p) => {
                self.phase = if p.ramping {
                    format!("ramping ({:+.3} °/s)", p.rate)
                } else {
                    format!(
                        "waiting for at-rate ({:.1} s stable of {:.1} s)",
                        p.stable_for.as_secs_f64(),
                        p.window.as_secs_f64()
                    )
                };
                self.redraw();
            }
            Event::Phase { phase, .. } => {
                self.phase = match phase {
                    Phase::Ramping => "ramping",
                    Phase::Settling => "settling",
                    Phase::Acquiring => "acquiring",
                    Phase::Fetching => "fetching readings",
                }
                .into();
                self.redraw();
            }
            Event::Acquiring {
                done,
                total,
                latest,
                mean,
                std,
            } => {
                if let Some(open) = self.open.last_mut() {
                    open.2 = done;
                }
                let latest = latest.map_or("overload".into(), |v| format!("{v:.6} V"));
                let spread = std.map_or(String::new(), |s| format!(", σ {s:.1e}"));
                self.phase = format!("{done}/{total}: {latest} (mean {mean:.6}{spread})");
                if self.tty {
                    self.redraw();
                }
            }
            Event::StepDone(r) => {
                self.open.retain(|(index, ..)| *index != r.step);
                self.line(format!(
                    "  step {} done: {:+.4} °/s -> {:.6} V (σ {:.1e} V, n {}, overloads {})",
                    r.step + 1,
                    r.rate_dps,
                    r.volts,
                    r.volts_std.unwrap_or(f64::NAN),
                    r.n,
                    r.overloads
                ));
            }
            Event::Warmup(w) => {
                let tol = w
                    .tolerance_v
                    .map_or("not yet estimated".into(), |t| format!("{t:.1e} V"));
                let change = w.last_change_v.map_or("-".into(), |c| format!("{c:.1e} V"));
                if !w.complete {
                    self.phase = format!(
                        "warm-up: window means change {change} (settled below {tol}), at most {}",
                        hms(w.max_s)
                    );
                    if self.tty {
                        self.redraw();
                    } else if w.mode == gyrocal_run::monitor::WARMUP_BEFORE_SWEEP {
                        say!("  {}", self.phase);
                    }
                } else if !self.warmup_reported {
                    self.warmup_reported = true;
                    let time = hms(w.time_s.unwrap_or(0.0));
                    self.line(if w.ended_by.as_deref() == Some("max") {
                        format!(
                            "warm-up ended at its maximum ({time}) WITHOUT settling: the last window means changed by {change} (settled below {tol})"
                        )
                    } else {
                        format!(
                            "warm-up complete after {time}: consecutive {:.1} s window means agree within {tol}",
                            w.window_s
                        )
                    });
                }
            }
            Event::Drift {
                segment,
                of,
                readings,
                elapsed_s,
                adev_v,
            } => {
                let adev = adev_v
                    .iter()
                    .map(|(tau, s)| format!("{} s {s:.2e} V", significant3(*tau)))
                    .collect::<Vec<_>>()
                    .join(" · ");
                let left = self.remaining().map_or(String::new(), |r| {
                    format!(", about {} left", hms(r.as_secs_f64()))
                });
                self.line(format!(
                    "  record: segment {segment}/{of} at {}{left}, {readings} readings this session{}",
                    hms(elapsed_s),
                    if adev.is_empty() {
                        String::new()
                    } else {
                        format!("; running ADEV at τ {adev}")
                    }
                ));
            }
            Event::Retry(r) => self.line(format!("  retry ({}): {}", r.instrument, r.message)),
            Event::Stopping {
                from_dps,
                emergency,
                deadline,
            } => {
                for (_, label, readings) in std::mem::take(&mut self.open) {
                    self.line(format!(
                        "{label}: not recorded ({readings} reading(s) discarded); it is measured \
                         again when the run is resumed"
                    ));
                }
                let how = if emergency {
                    "emergency stop sent"
                } else {
                    "controlled stop sent"
                };
                let text = match from_dps {
                    Some(r) if r.abs() > 1e-3 => format!(
                        "{how}: table decelerating from {r:+.3} °/s … (waiting up to {} for rest)",
                        hms(deadline.as_secs_f64())
                    ),
                    Some(r) => format!("{how}: table measured at {r:+.4} °/s, confirming rest …"),
                    None => format!(
                        "{how}: no rate measured (the table did not answer in time); waiting up \
                         to {} for rest …",
                        hms(deadline.as_secs_f64())
                    ),
                };
                self.step = None;
                self.phase = "stopping the table".into();
                self.redraw();
                self.line(text);
            }
            Event::Rest(rest) => self.line(rest_text(&rest)),
        }
    }
}

/// A τ with three significant digits (`1.39`, `11.1`, `88.8`).
fn significant3(v: f64) -> String {
    if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// `1:02:03` or `2:03` (a countdown that fits a narrow line).
fn short_hms(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    let (h, m, sec) = (s / 3600, (s / 60) % 60, s % 60);
    if h > 0 {
        format!("{h}:{m:02}:{sec:02}")
    } else {
        format!("{m}:{sec:02}")
    }
}

/// The operator's line about the table at the end of a run: "at rest" only when the table
/// said so.
fn rest_text(rest: &TableRest) -> String {
    match rest {
        TableRest::AtRest { rate_dps, waited } => format!(
            "table at rest ({rate_dps:+.4} °/s, mode OFF, after {:.1} s)",
            waited.as_secs_f64()
        ),
        TableRest::NotConfirmed { reason } => {
            format!("the table could NOT be confirmed at rest: stop it by hand ({reason})")
        }
        TableRest::NeverReached { reason } => {
            format!("the table could NOT be confirmed at rest: {reason}; check it is not turning")
        }
        TableRest::NoTable => "no rate table in this plan: nothing was moved".into(),
    }
}

fn line(tty: bool, bar: &indicatif::ProgressBar, text: String) {
    if tty {
        bar.println(text);
    } else {
        say!("{text}");
    }
}

/// The command line that continues this run, with the options it was started with.
fn resume_command(args: &RunArgs, dir: &Path) -> String {
    // the run's plan is in its manifest: the resume needs no plan file (one that was edited
    // since would be refused)
    let mut c = "gyrocal run".to_string();
    if args.simulate {
        c.push_str(" --simulate");
    }
    if let Some(x) = args.sim_time_scale {
        c.push_str(&format!(" --sim-time-scale {x}"));
    }
    if let Some(p) = &args.dmm_port {
        c.push_str(&format!(" --dmm-port {p}"));
    }
    if let Some(p) = &args.table_port {
        c.push_str(&format!(" --table-port {p}"));
    }
    c.push_str(&format!(" --resume {}", dir.display()));
    c
}

/// After the sequencer: fit, report, the closing summary; the exit code. The last line says
/// where the table was left whenever that is not "at rest, as the table reported".
fn finish(
    args: &RunArgs,
    dir: &Path,
    summary: &RunSummary,
    mut run: RunDir,
    signal: Option<StopSignal>,
    doc: &mut serde_json::Value,
) -> anyhow::Result<u8> {
    // human text on stdout, or on stderr when stdout carries the JSON document
    let human = |text: String| {
        if args.json {
            say!("{text}");
        } else {
            out!("{text}");
        }
    };
    let resume = summary.resumable.then(|| resume_command(args, dir));
    let table = match &summary.table {
        TableRest::AtRest { rate_dps, waited } => serde_json::json!({
            "at_rest": true, "rate_dps": rate_dps, "waited_s": waited.as_secs_f64(),
        }),
        TableRest::NotConfirmed { reason } | TableRest::NeverReached { reason } => {
            serde_json::json!({ "at_rest": false, "reason": reason })
        }
        // nothing can be turning: at rest in the sense a script checks for
        TableRest::NoTable => serde_json::json!({ "at_rest": true, "none": true }),
    };
    let m = run.manifest();
    doc["run_dir"] = serde_json::json!(dir);
    doc["status"] = serde_json::json!(summary.status);
    doc["reason"] = serde_json::json!(summary.reason);
    doc["emergency_stop"] = serde_json::json!(summary.emergency_stop);
    doc["table"] = table;
    doc["steps_recorded_this_session"] = serde_json::json!(summary.steps_recorded);
    doc["steps_done"] = serde_json::json!(run.done_steps().len());
    doc["steps_total"] = serde_json::json!(run.schedule().len());
    doc["elapsed_s"] = serde_json::json!(summary.elapsed_s);
    doc["timing"] = serde_json::json!(summary.timing);
    doc["simulated"] = serde_json::json!(m.simulated);
    // the warm-up as watched online (plans with [warmup])
    doc["warmup"] = serde_json::json!(m.warmup);
    doc["resume_command"] = serde_json::json!(match summary.status {
        Status::Complete => None,
        _ => resume,
    });
    let code = finish_human(args, dir, summary, &mut run, signal, &human, doc);
    catalog_close(dir, doc);
    let code = code?;
    doc["exit_code"] = serde_json::json!(code);
    Ok(code)
}

/// The end of a complete drift run: the record is analysed by Allan deviation, not fitted.
fn finish_drift(
    args: &RunArgs,
    dir: &Path,
    run: &mut RunDir,
    human: &dyn Fn(String),
    doc: &mut serde_json::Value,
) -> anyhow::Result<u8> {
    if args.no_report {
        human(format!(
            "drift record complete: analyse it with `gyrocal allan {}` (--scale-factor K for °/h)",
            dir.display()
        ));
    } else {
        // the analysis finds the scale factor itself (the run's fit.json, or the simulated
        // gyro's); without one the record stays in volts
        // through the run directory still open: allan.json and allan.html are recorded in
        // the manifest with their SHA-256, under the run's lock
        match gyrocal_report::write_allan_into(run, &Default::default(), &[]) {
            Ok((a, files)) => {
                doc["allan"] = serde_json::json!({
                    "files": files,
                    "unit": a.unit,
                    "scale_factor": a.scale_factor,
                    "noise_terms": a.noise_terms,
                    "bias": a.bias,
                    "warmup": a.warmup,
                });
                human(format!(
                    "drift record complete: Allan analysis in {}{}",
                    files
                        .iter()
                        .map(|f| f.display().to_string())
                        .collect::<Vec<_>>()
                        .join(" and "),
                    match &a.scale_factor {
                        Some(k) => format!(
                            " (K = {} V/(°/s), {}, converts to °/h)",
                            k.v_per_dps, k.source
                        ),
                        None => format!(
                            " (in volts: `gyrocal allan {} --scale-factor K` for °/h)",
                            dir.display()
                        ),
                    }
                ));
            }
            Err(e) => say!(
                "gyrocal: warning: {} (the record is complete: `gyrocal report {}` writes the analysis again)",
                e.allan_warning(),
                dir.display()
            ),
        }
    }
    human(format!("run directory: {}", dir.display()));
    Ok(0)
}

/// How long the end of a run waits for the catalog to take the run's last state.
const CATALOG_CLOSE_TIMEOUT: Duration = Duration::from_secs(5);

/// Gives the catalog the run's final state and waits (bounded) for it; says so when the
/// catalog could not be updated: the run directory has everything, an import catches up.
fn catalog_close(dir: &Path, doc: &mut serde_json::Value) {
    let Some((writer, _)) = CATALOG.lock().ok().and_then(|mut slot| slot.take()) else {
        return;
    };
    writer.finished(dir);
    let url = writer.url().to_string();
    let updated = writer.close(CATALOG_CLOSE_TIMEOUT);
    doc["catalog"] = serde_json::json!({ "url": url, "updated": updated });
    if !updated {
        say!(
            "gyrocal: warning: the catalog {url} could not be updated (see run.log); the run directory is complete: `gyrocal catalog import {}` brings the catalog up to date",
            dir.display()
        );
    }
}

/// The human side of [`finish`]: the closing lines, the fit and the report.
fn finish_human(
    args: &RunArgs,
    dir: &Path,
    summary: &RunSummary,
    run: &mut RunDir,
    signal: Option<StopSignal>,
    human: &dyn Fn(String),
    doc: &mut serde_json::Value,
) -> anyhow::Result<u8> {
    let rest_line = match &summary.table {
        TableRest::AtRest { .. } => "the table is at rest".to_string(),
        other => rest_text(other),
    };
    // before a resume the operator re-arms what the emergency stop opened
    let rearm = if summary.emergency_stop {
        "\n  an EMERGENCY STOP was sent (it opens the table's interlock: servo off). Find out why \
         it was needed, make the table safe and re-arm the interlock at its controller before \
         resuming (the resume re-enables the servo and fails if the table refuses)"
    } else {
        ""
    };
    match summary.status {
        Status::Complete => {}
        Status::Aborted => {
            say!(
                "gyrocal: run aborted: {}\n  {} step(s) recorded this session (a step cut short \
                 is not recorded: it is measured afresh on resume); resume with: {}{rearm}\n  \
                 {rest_line}",
                summary.reason.as_deref().unwrap_or("stopped"),
                summary.steps_recorded,
                resume_command(args, dir)
            );
            return Ok(signal.map_or(EXIT_ABORTED, |s| s.exit_code));
        }
        Status::Failed | Status::Running => {
            let next = if summary.resumable {
                format!("resume with: {}", resume_command(args, dir))
            } else {
                // the plan must change, so the same run cannot go on
                "fix the plan and start a new run (a changed plan cannot resume this one)"
                    .to_string()
            };
            say!(
                "gyrocal: run failed: {}\n  {} step(s) recorded this session; {next}{rearm}\n  \
                 {rest_line}",
                summary.reason.as_deref().unwrap_or("unknown"),
                summary.steps_recorded,
            );
            return Ok(1);
        }
    }
    // one ending for every kind of complete run: its results, then the table's rest state
    // decides the last line and the exit code
    let code = if run.manifest().plan.kind() == gyrocal_run::PlanKind::Drift {
        finish_drift(args, dir, run, human, doc)?
    } else {
        finish_sweep(args, dir, summary, run, human, doc)?
    };
    if !summary.table.nothing_turning() {
        say!(
            "gyrocal: all steps recorded, but {}",
            rest_text(&summary.table)
        );
        return Ok(1);
    }
    Ok(code)
}

/// The end of a complete sweep: the fit, the timing and the report.
fn finish_sweep(
    args: &RunArgs,
    dir: &Path,
    summary: &RunSummary,
    run: &mut RunDir,
    human: &dyn Fn(String),
    doc: &mut serde_json::Value,
) -> anyhow::Result<u8> {
    let analysis = fit_run(run, &gyrocal_fit::Options::default())
        .with_context(|| format!("fitting {}", dir.display()))?;
    doc["fit"] = serde_json::json!(run.manifest().fit_summary);
    doc["acceptance"] = serde_json::json!(run.manifest().acceptance);
    let mut out = String::new();
    crate::cmd::fit::human(&mut out, &analysis);
    human(out);
    if let Some(t) = &summary.timing {
        human(format!(
            "timing: schedule {} (run clock), physical bound {}, ratio {:.4} (acquisition {}); \
             elapsed {} with connecting and the stop",
            hms(t.elapsed_s),
            hms(t.bound_s),
            t.ratio,
            t.acquisition.as_deref().unwrap_or("?"),
            hms(summary.elapsed_s)
        ));
    }
    if !args.no_report {
        // the data and the fit are safe on disk already: a report failure is a warning
        match gyrocal_report::write_run_report(dir) {
            Ok(path) => {
                doc["report"] = serde_json::json!(path);
                human(format!("report: {}", path.display()));
            }
            Err(e) => say!("gyrocal: warning: no report: {e}"),
        }
    }
    human(format!("run directory: {}", dir.display()));
    Ok(0)
}
