//! What a run records before its instruments move: the gyro, the station and its
//! calibration records, the catalog, the run directory (created, or opened for a resume with
//! its checks), the log file.

use super::*;

/// Deviations known before the run directory exists: (kind, text).
pub(super) type PendingDeviations = Vec<(String, String)>;

/// What a run records about the gyro, the station and the departures known before it starts.
pub(super) struct Records {
    pub(super) dut: Option<gyrocal_files::Dut>,
    pub(super) station: Option<gyrocal_files::station::Station>,
    /// (kind, text) of each deviation to record when the run directory is open.
    pub(super) deviations: PendingDeviations,
    /// Where the run is indexed (`None`: not at all).
    pub(super) catalog: Option<gyrocal_catalog::CatalogUrl>,
}

/// The catalog writer of this process's run and the run directory it indexes: set when the
/// run directory is open, told of every step by the progress view, closed at the end. One
/// run per process, so one slot.
pub(super) static CATALOG: std::sync::Mutex<Option<(gyrocal_catalog::CatalogWriter, PathBuf)>> =
    std::sync::Mutex::new(None);

/// Tells the catalog writer (if any) about the run; never blocks on the catalog.
pub(super) fn catalog_note(f: impl FnOnce(&gyrocal_catalog::CatalogWriter, &Path)) {
    if let Ok(slot) = CATALOG.lock()
        && let Some((w, dir)) = slot.as_ref()
    {
        f(w, dir);
    }
}

/// The catalog for this run: `--catalog`, `$GYROCAL_CATALOG`, the station's `catalog`, the
/// default SQLite file; `off` (or `none`) in the flag or the variable turns it off. A bad
/// `--catalog` is bad input; any other catalog trouble is a warning (the run goes on).
pub(super) fn catalog_url(
    args: &RunArgs,
    station: Option<&gyrocal_files::station::Station>,
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
pub(super) fn dut_for_run(args: &RunArgs, plan: &Plan) -> Option<gyrocal_files::Dut> {
    let from_plan = plan.dut().cloned().unwrap_or_default();
    let mut dut = from_plan.overridden_by(gyrocal_files::Dut {
        serial: args.dut_serial.clone(),
        model: args.dut_model.clone(),
        ..gyrocal_files::Dut::default()
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
pub(super) fn station_for_run(
    args: &RunArgs,
    plan: &Plan,
    sim_seed: u64,
) -> anyhow::Result<(Option<gyrocal_files::station::Station>, PendingDeviations)> {
    use gyrocal_files::station::Station;
    let today = jiff::Zoned::now().date();
    let needs = gyrocal_files::station::Needs::of_plan(plan);
    // where the records come from, for the refusal's message
    let (station, source) = match Station::resolve(args.station.as_deref())
        .map_err(|e| BadInput(format!("station: {e}")))?
    {
        Some((path, s)) => {
            say!("station: {} ({})", s.id, path.display());
            for line in crate::cmd::check::station_warnings(&s, &path, needs) {
                say!("gyrocal: warning: {line}");
            }
            (Some(s), path.display().to_string())
        }
        None if args.simulate => (
            Some(Station::simulated_for(sim_seed, today, plan)),
            "the simulated bench's records".to_string(),
        ),
        None => (None, String::new()),
    };
    let mut deviations = Vec::new();
    if let Some(s) = &station {
        // an instrument the plan does not use (a drift record's absent table, a sweep's
        // chamber): its calibration is moot; a series' chamber is refused like the meter
        let overdue = s.overdue_for(today, needs);
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
                let keys = overdue
                    .iter()
                    .map(|o| format!("[{}] due = {}", o.role, o.due))
                    .collect::<Vec<_>>()
                    .join(", ");
                return Err(BadInput(format!(
                    "{source}: {keys}: station {}: {list} (today is {today}): calibrate it, or \
                     start with --allow-expired, which the report records as a deviation",
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

pub(super) fn open_run_dir(
    args: &RunArgs,
    plan: &Plan,
    records: Records,
) -> anyhow::Result<(PathBuf, RunDir)> {
    let station_serve = records.station.as_ref().and_then(|s| s.serve.clone());
    let (dir, mut run) = open_run_dir_inner(args, plan, records.dut, records.station)?;
    SessionClock::note(&run, args);
    for (kind, text) in &records.deviations {
        // a resume on the same instruments finds the same departure: recorded once
        if run
            .manifest()
            .deviations
            .iter()
            .any(|d| d.kind == *kind && d.text == *text)
        {
            continue;
        }
        run.add_deviation(kind, text)
            .map_err(|e| anyhow::anyhow!("{}: recording a deviation: {e}", dir.display()))?;
    }
    if let Some(url) = records.catalog {
        tracing::info!(catalog = %url, "indexing the run");
        live::start_bus(&url);
        let writer = gyrocal_catalog::CatalogWriter::spawn(url);
        writer.register(&dir);
        if let Ok(mut slot) = CATALOG.lock() {
            *slot = Some((writer, dir.clone()));
        }
    }
    live::announce(args, station_serve.as_deref(), &dir);
    Ok((dir, run))
}

pub(super) fn open_run_dir_inner(
    args: &RunArgs,
    plan: &Plan,
    dut: Option<gyrocal_files::Dut>,
    station: Option<gyrocal_files::station::Station>,
) -> anyhow::Result<(PathBuf, RunDir)> {
    let virtual_time = args.simulate;
    // the environment as entered, else the station's usual conditions
    let context = gyrocal_files::RunContext {
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
        context: (context != gyrocal_files::RunContext::default()).then_some(context),
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
        let noun = if plan.kind() == gyrocal_files::PlanKind::Drift {
            "segments"
        } else {
            "steps"
        };
        say!(
            "resuming {}: {done} of {} {noun} done, {} to go; the run clock goes on from {} \
             (this session's times count from there)",
            dir.display(),
            run.schedule().len(),
            run.remaining_steps().len(),
            hms(run.manifest().elapsed_s)
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
pub(super) fn station_words(s: &gyrocal_files::station::Station) -> String {
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
pub(super) fn station_change(
    started: Option<&gyrocal_files::station::Station>,
    now: Option<&gyrocal_files::station::Station>,
) -> Option<String> {
    let key = |s: &gyrocal_files::station::Station| {
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
pub(super) fn check_resume_dut(dir: &Path, serial: Option<&str>) -> anyhow::Result<()> {
    let Some(serial) = serial else {
        return Ok(());
    };
    let path = dir.join(gyrocal_files::rundir::MANIFEST_JSON);
    let Ok(bytes) =
        gyrocal_files::rundir::read_capped(&path, gyrocal_files::rundir::MAX_MANIFEST_BYTES)
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
pub(super) fn check_resume_mode(dir: &Path, simulate: bool) -> anyhow::Result<()> {
    let path = dir.join(gyrocal_files::rundir::MANIFEST_JSON);
    let Ok(bytes) =
        gyrocal_files::rundir::read_capped(&path, gyrocal_files::rundir::MAX_MANIFEST_BYTES)
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
pub(super) fn attach_log(dir: &Path) {
    let path = dir.join("run.log");
    if let Err(e) = crate::runlog::attach(&path) {
        say!("gyrocal: warning: no run log at {}: {e}", path.display());
    }
}

pub(super) fn default_dir(plan: &Path) -> PathBuf {
    let stem = plan.file_stem().and_then(|s| s.to_str()).unwrap_or("run");
    let now = gyrocal_files::rfc3339_utc(std::time::SystemTime::now()).replace(':', "");
    PathBuf::from("runs").join(format!("{stem}-{now}"))
}
