//! Building the bench and running the engine: the instruments' links opened (or the simulated
//! bench spawned), the bench built by [`crate::instruments`], the engine run with the signals
//! watched and the progress shown.

use gyrocal_files::station::SerialCheck;
use gyrocal_run::{Bench, Engine};

use super::*;

/// Opens the instruments' links (or builds the simulated bench), then the run directory (so a
/// port that does not open leaves no run directory behind), and runs the sequencer.
pub(super) async fn execute(
    args: &RunArgs,
    plan: Plan,
    faults: &[gyrocal_sim::faults::FaultSpec],
    mut records: Records,
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
        let mut bench = gyrocal_sim::bench::Bench::spawn(cfg);
        // the real chamber driver over the simulated controller's link (none without [chamber])
        let mut chamber = crate::chamber::simulated(&plan, bench.chamber_link())?;
        let mut schedule = gyrocal_sim::faults::schedule(faults, &bench.handle, time_scale);
        check_chamber(&mut chamber, &mut records).await?;
        let (dir, run) = open_run_dir(args, &plan, records)?;
        let (summary, run, signal) = match &plan.dmm().port {
            // the plan reaches the meter over GPIB: the bench put a simulated Prologix
            // controller in front of it, and the real Prologix transport talks to that
            port if port.is_gpib() => {
                let options = port.prologix_options().cloned().unwrap_or_default();
                let dmm = gyrocal_link::PrologixTransport::open(bench.dmm, options)
                    .await
                    .context("opening the simulated Prologix controller")?;
                sequence(plan, dmm, Some(bench.table), chamber, run).await?
            }
            // a Truevolt on its LAN socket: device clear reconnects to the simulated meter
            _ if plan.dmm().scpi_socket() => {
                let Some(lan) = bench.handle.lan.clone() else {
                    anyhow::bail!("the simulated bench has no LAN meter for a Truevolt plan");
                };
                let dmm = gyrocal_link::SocketTransport::new(bench.dmm.boxed(), lan.connector());
                sequence(plan, dmm, Some(bench.table), chamber, run).await?
            }
            _ => sequence(plan, bench.dmm, Some(bench.table), chamber, run).await?,
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
        let mut state = serde_json::json!({
            "table": {
                "mode": format!("{:?}", t.mode()),
                "demanded_dps": t.demanded_rate(),
                "stopped": t.is_stopped(),
                "interlock_closed": t.interlock_closed(),
            }
        });
        // and what the simulated chamber itself holds (the run's account came from its driver)
        if let Some(c) = &bench.handle.chamber {
            let now = tokio::time::Instant::now();
            let temps = c.temperatures(now);
            say!(
                "simulated chamber at the end: setpoint {:.1} °C, mode {:?}, air {:.1} °C, gyro inside {:.1} °C",
                c.setpoint_c(),
                c.mode(),
                temps.air_c,
                c.inside_c(now)
            );
            state["chamber"] = serde_json::json!({
                "setpoint_c": c.setpoint_c(),
                "mode": format!("{:?}", c.mode()),
                "air_c": temps.air_c,
                "alarms": c.alarms().iter().map(|a| format!("{a:?}")).collect::<Vec<_>>(),
            });
        }
        Ok((dir, summary, run, signal, Some(state)))
    } else {
        // Every instrument must answer before anything is created on disk.
        let flags = crate::cmd::probe::PortFlags {
            dmm: args.dmm_port.is_some(),
            table: args.table_port.is_some(),
        };
        let found = crate::cmd::probe::probe(&plan, flags).await?;
        say!(
            "probe: both instruments answer (the table in mode {} at {:+.4} °/s)",
            found.table_mode,
            found.table_rate_dps
        );
        if let Some(station) = &records.station {
            // the station's records must be these instruments': a mismatch is recorded
            let checks = crate::cmd::probe::serial_checks(station, &found);
            note_checks(checks, &station.id, &mut records.deviations, |_| true);
        }
        let d = plan.dmm();
        let dmm = gyrocal_link::open_port(&d.port, &crate::cmd::probe::dmm_link_options(&plan))
            .await
            .with_context(|| format!("opening the multimeter at {}", d.port))?;
        let t = plan.table();
        let table = if plan.has_table() {
            Some(
                gyrocal_link::open_port(&t.port, &crate::cmd::probe::table_link_options(&plan))
                    .await
                    .with_context(|| format!("opening the rate table at {}", t.port))?,
            )
        } else {
            None
        };
        let mut chamber = crate::chamber::open(&plan, args.chamber_port.as_deref()).await?;
        check_chamber(&mut chamber, &mut records).await?;
        let (dir, run) = open_run_dir(args, &plan, records)?;
        let (summary, run, signal) = sequence(plan, dmm, table, chamber, run).await?;
        Ok((dir, summary, run, signal, None))
    }
}

/// The chamber of a series identified before anything is created on disk (as the probe
/// asks the meter and the table), and the station's `[chamber]` compared with the controller
/// that answered ([`gyrocal_files::station::Station::check_chamber`]): another controller
/// than the record names is a warning and a recorded deviation, since the certificate would
/// name another chamber's calibration. Nothing for a run without a chamber. The engine
/// connects again when the run starts (reads only: the identity and the units).
async fn check_chamber(
    chamber: &mut gyrocal_chamber::AnyChamber,
    records: &mut Records,
) -> anyhow::Result<()> {
    use gyrocal_chamber::Chamber as _;
    if !chamber.present() {
        return Ok(());
    }
    let describe = chamber.describe().to_string();
    let id = chamber
        .connect()
        .await
        .with_context(|| format!("the chamber at {describe} did not identify itself"))?;
    let Some(station) = &records.station else {
        return Ok(());
    };
    // the controller's model is what it tells; it reports no serial (not said at each run)
    let checks = station.check_chamber(Some(id.model.as_str()), None);
    note_checks(checks, &station.id, &mut records.deviations, |c| {
        matches!(c, SerialCheck::ModelMatch { .. })
    });
    Ok(())
}

/// The station's checks of the instruments that answered: a mismatch is a warning and a
/// recorded deviation (the certificate would name another instrument's calibration); the
/// others are said when `said` says so.
fn note_checks(
    checks: Vec<SerialCheck>,
    station_id: &str,
    deviations: &mut PendingDeviations,
    said: impl Fn(&SerialCheck) -> bool,
) {
    for c in checks {
        let words = c.words(station_id);
        if c.is_mismatch() {
            say!("gyrocal: warning: {words} (recorded as a deviation)");
            deviations.push((gyrocal_files::station::SERIAL_MISMATCH.to_string(), words));
        } else if said(&c) {
            say!("station: {words}");
        }
    }
}

/// The longest single jump of the paced clock. Timers that fall within one jump complete "at
/// the same time" and tokio polls them in any order, so a simulated instrument's reply due a
/// few ms after its request could lose to the request's deadline: at 10000× (10 s a jump) six
/// paced runs of configs/series.toml out of six failed with "no reply within 333 ms" from the
/// simulated table. 20 ms keeps each reply ahead of the drivers' deadlines (hundreds of ms).
const PACE_MAX_JUMP: Duration = Duration::from_millis(20);

/// Paces the paused (virtual) clock at `x` simulated seconds per real second: a real sleep
/// on the blocking pool (while it runs, tokio does not auto-advance the paused clock), then
/// the clock advanced by `x` times as much, in jumps of at most [`PACE_MAX_JUMP`] with the
/// woken tasks run between them. Everything on the clock (the simulated instruments, the
/// sequencer's waits) keeps its order and its exact virtual timings.
pub(super) async fn pace(x: f64) {
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
        let mut left = step;
        while !left.is_zero() {
            let jump = left.min(PACE_MAX_JUMP);
            tokio::time::advance(jump).await;
            tokio::task::yield_now().await;
            left -= jump;
        }
    }
}

/// The instruments the plan names, built on their links by [`crate::instruments`] (the one
/// place that knows the drivers), then the same generic sequence for every combination.
pub(super) async fn sequence<D, T>(
    plan: Plan,
    dmm_link: D,
    table_link: Option<T>,
    chamber: gyrocal_chamber::AnyChamber,
    run: RunDir,
) -> anyhow::Result<(RunSummary, RunDir, Option<StopSignal>)>
where
    D: Transport + 'static,
    T: Transport + 'static,
{
    let p = plan.clone();
    let job = Sequence { plan, run };
    crate::instruments::with_instruments(&p, dmm_link, table_link, chamber, job).await
}

/// The run's job once its instruments are built.
pub(super) struct Sequence {
    plan: Plan,
    run: RunDir,
}

impl crate::instruments::WithInstruments for Sequence {
    type Output = anyhow::Result<(RunSummary, RunDir, Option<StopSignal>)>;

    async fn call<B>(self, bench: B) -> Self::Output
    where
        B: Bench + 'static,
    {
        sequence_with(self.plan, bench, self.run).await
    }
}

/// Runs the engine with signals watched and progress shown, whatever the instruments.
pub(super) async fn sequence_with<B>(
    plan: Plan,
    bench: B,
    run: RunDir,
) -> anyhow::Result<(RunSummary, RunDir, Option<StopSignal>)>
where
    B: Bench + 'static,
{
    let (tx, rx) = mpsc::unbounded_channel();
    let view = ViewContext::of(&plan, &run);
    // live.json for viewers (gyrocal serve); never a reason for the run to wait or fail
    // (and to the catalog's bus when it is PostgreSQL)
    let live = live::live_sink(&run);
    let mut seq = Engine::on_bench(plan, bench, run, SequencerOptions::default())
        .with_events(tx)
        .with_sink(live);
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
    let display = tokio::spawn(show_progress(rx, view));
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
pub(super) async fn watch_signals(
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
