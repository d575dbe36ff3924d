//! `gyrocal sim`: the simulated bench (HP 34401A, ACL rate table, HRG gyro) on two
//! pseudo-terminals, and optionally the table on a TCP port, in real time; with `--chamber`
//! a thermal chamber around the gyro too (a Watlow F4 on a pseudo-terminal, Modbus RTU, or on
//! a Modbus TCP port with `--chamber-tcp`; an Espec on a pseudo-terminal).
//!
//! Output contract (stdout, one JSON object per line, nothing else):
//!
//! 1. once the bench serves: `{"dmm": "/dev/pts/N", "dmm_port": "<the plan's [dmm] port>",
//!    "table": "/dev/pts/M",
//!    ["table_tcp": "tcp://127.0.0.1:P",] ["chamber": "/dev/pts/K" or "tcp://127.0.0.1:P",
//!    "chamber_model": "watlow_f4"|"espec",] "pid", "seed", "time_scale", "truth": {...},
//!    "faults": ["dmm:garble@reading100", ...]}`;
//! 2. on SIGINT or SIGTERM, before exiting with 0: `{"exit": "SIGINT"|"SIGTERM", "table":
//!    {"mode", "demanded_rate", "actual_rate", "stopped", "interlock_closed", "fault",
//!    "silent", "demands_seen"}, "dmm": {"readings_taken", ...}, ["chamber": {"setpoint_c",
//!    "air_c", "case_c", "inside_c", "alarms", "requests_seen"},] "faults": [{"spec",
//!    "fired"}]}`;
//! 3. meanwhile, on each SIGUSR1 (the operator pressing the alarm reset at the simulated
//!    chamber's panel: its latched alarms cleared): `{"chamber_panel": "alarms reset",
//!    "cleared": ["door open", ...]}`.
//!
//! Logs go to stderr. The slave side of each pseudo-terminal stays open in this process for as
//! long as it runs, so a client may close its port and open the same path again (a resumed
//! run does): the simulators never see a hang-up and keep their state.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Args;
use gyrocal_sim::bench::{Bench, BenchConfig, BenchHandle};
use gyrocal_sim::faults::{self, FaultSchedule, FaultSpec};
use serde_json::{Value, json};

use crate::BadInput;

/// Arguments of `gyrocal sim`.
#[derive(Debug, Args)]
#[command(after_long_help = after_help())]
pub struct SimArgs {
    /// Bench configuration: a simulator TOML (seed, time_scale, [table], [gyro], [dmm]) or a
    /// test plan, whose [simulation] section and link settings are used (told apart by content:
    /// a file with a [plan] or [simulation] table is a plan). Default: the simulator's defaults.
    #[arg(long, value_name = "FILE|PLAN")]
    pub config: Option<PathBuf>,
    /// Sim seconds per real second for the instruments' own timing (integration, transfers,
    /// table dynamics); overrides the configuration's. Default 1 (real instrument timing).
    #[arg(long, value_name = "X")]
    pub time_scale: Option<f64>,
    /// Seed of every random stream; overrides the configuration's.
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Schedule a fault (repeatable): DEVICE:ACTION@TRIGGER[xCOUNT][/Ss], such as
    /// dmm:garble@reading100 or table:trip@demand4 (see below).
    #[arg(long = "fault", value_name = "SPEC")]
    pub faults: Vec<String>,
    /// Also serve the table on tcp://127.0.0.1:PORT (0 picks a free port; the JSON line says
    /// which), in addition to its pseudo-terminal. Clients may use either; both drive the same
    /// table.
    #[arg(long, value_name = "PORT")]
    pub table_tcp: Option<u16>,
    /// The multimeter: 34401a (on its RS-232 port, the default) or a Keysight Truevolt
    /// (34460a, 34461a, 34465a, 34470a), served on its SCPI socket tcp://127.0.0.1:P (the JSON
    /// line's "dmm"). Default: the configuration's.
    #[arg(long, value_name = "MODEL")]
    pub dmm: Option<String>,
    /// How the multimeter is reached: serial (a 34401A's RS-232 port), prologix (a 34401A
    /// on GPIB behind a simulated Prologix GPIB-USB controller, on a pseudo-terminal),
    /// prologix-tcp (the same behind a GPIB-ETHERNET controller, on tcp://127.0.0.1:P) or lan
    /// (a Truevolt's socket, the only link a Truevolt has here). The JSON line's "dmm_port" is
    /// the plan's `[dmm] port` for it. Default: the configuration's.
    #[arg(long, value_name = "LINK", value_parser = ["serial", "prologix", "prologix-tcp", "lan"])]
    pub link: Option<String>,
    /// The table's dialect: acl or aerosmith. Default: the configuration's.
    #[arg(long, value_name = "DIALECT", value_parser = ["acl", "aerosmith"])]
    pub table: Option<String>,
    /// A thermal chamber around the gyro: watlow_f4 (Modbus RTU on a pseudo-terminal) or
    /// espec (text lines on a pseudo-terminal); the JSON line's "chamber" is its path. The
    /// gyro's scale factor and bias follow its inside temperature (the configuration's
    /// tempcos). Default: the configuration's chamber, if any.
    #[arg(long, value_name = "MODEL", value_parser = ["watlow_f4", "espec"])]
    pub chamber: Option<String>,
    /// Serve the chamber (a Watlow F4) as Modbus TCP on tcp://127.0.0.1:PORT instead of a
    /// pseudo-terminal (0 picks a free port; the JSON line's "chamber" says which).
    #[arg(long, value_name = "PORT")]
    pub chamber_tcp: Option<u16>,
}

const AFTER_HELP: &str = "\
Output: one JSON line on stdout once the bench serves, with the device paths and the truth:
  {\"dmm\": \"/dev/pts/N\", \"dmm_port\": \"(the plan's [dmm] port)\", \"table\": \"/dev/pts/M\",
   [\"table_tcp\": \"tcp://127.0.0.1:P\",]
   \"pid\": ..., \"seed\": ..., \"time_scale\": ..., \"truth\": {\"k0\", \"k1_pos\", \"k1_neg\", \"k2\",
   \"k3\", \"earth_rate\"}, \"faults\": [...]}
then, on SIGINT or SIGTERM, one more line before exiting with 0:
  {\"exit\": \"SIGINT\", \"table\": {\"mode\", \"demanded_rate\", \"actual_rate\", \"stopped\",
   \"interlock_closed\", \"fault\", \"silent\", \"demands_seen\"}, \"dmm\": {\"readings_taken\",
   \"commands_seen\", \"lines_seen\", \"queries_answered\", \"device_clears\", \"errors_raised\",
   \"remote\", \"stopped\", \"power_cycles\", \"nplc\", \"late_replies\"}, \"faults\": [{\"spec\",
   \"fired\"}]}
SIGUSR1 is the operator pressing the alarm reset at the simulated chamber's panel: its latched
alarms are cleared (a run stopped by one can then be resumed), and a line says so:
  {\"chamber_panel\": \"alarms reset\", \"cleared\": [\"door open\"]}
Clients may close a port and open the same path again; the simulators keep their state.

Fault specs (--fault, repeatable):
";

fn after_help() -> String {
    format!("{AFTER_HELP}{}", faults::GRAMMAR)
}

/// Runs `gyrocal sim` until SIGINT or SIGTERM.
pub fn run(args: &SimArgs) -> Result<()> {
    let mut specs = Vec::with_capacity(args.faults.len());
    for text in &args.faults {
        let spec: FaultSpec = text.parse().map_err(|e: faults::FaultSpecError| {
            BadInput(format!("{e} (the grammar is in `gyrocal sim --help`)"))
        })?;
        specs.push(spec);
    }
    let mut config = match &args.config {
        Some(path) => load_config(path)?,
        None => BenchConfig::default(),
    };
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    if let Some(x) = args.time_scale {
        config.time_scale = x;
    }
    if let Some(model) = &args.dmm {
        config.dmm_model = model
            .parse::<gyrocal_sim::bench::DmmModel>()
            .map_err(|e| BadInput(format!("--dmm: {e}")))?;
    }
    match args.link.as_deref() {
        Some("serial") => config.dmm_link = gyrocal_sim::bench::DmmLink::Rs232,
        Some("prologix") | Some("prologix-tcp") => {
            config.dmm_link = gyrocal_sim::bench::DmmLink::Prologix(Default::default());
        }
        Some(_) => config.dmm_link = gyrocal_sim::bench::DmmLink::Lan,
        None => {}
    }
    let truevolt = config.dmm_model.truevolt().is_some();
    if truevolt
        && !matches!(
            config.dmm_link,
            gyrocal_sim::bench::DmmLink::Rs232 | gyrocal_sim::bench::DmmLink::Lan
        )
    {
        return Err(
            BadInput("a Truevolt is served on its LAN socket only (--link lan)".into()).into(),
        );
    }
    if !truevolt && config.dmm_link == gyrocal_sim::bench::DmmLink::Lan {
        return Err(BadInput(
            "--link lan is a Truevolt's (--dmm 34460a|34461a|34465a|34470a)".into(),
        )
        .into());
    }
    if let Some(model) = &args.chamber {
        let model = model
            .parse::<gyrocal_sim::chamber::ChamberModel>()
            .map_err(|e| BadInput(format!("--chamber: {e}")))?;
        let mut chamber = config.chamber.take().unwrap_or_default();
        chamber.model = model;
        config.chamber = Some(chamber);
    }
    if args.chamber_tcp.is_some() {
        match &mut config.chamber {
            None => config.chamber = Some(Default::default()),
            Some(c) if c.model != gyrocal_sim::chamber::ChamberModel::WatlowF4 => {
                return Err(BadInput(
                    "--chamber-tcp serves Modbus TCP: a Watlow F4's (--chamber watlow_f4)".into(),
                )
                .into());
            }
            Some(_) => {}
        }
    }
    if let Some(c) = &config.chamber {
        c.thermal
            .validate()
            .map_err(|e| BadInput(format!("simulated chamber: {e}")))?;
    }
    match args.table.as_deref() {
        Some("aerosmith") => {
            config.table_wire = gyrocal_sim::bench::TableWire::Aerosmith(Default::default());
        }
        Some(_) => config.table_wire = gyrocal_sim::bench::TableWire::Acl,
        None => {}
    }
    if !(config.time_scale.is_finite() && config.time_scale > 0.0 && config.time_scale <= 1e6) {
        return Err(BadInput(format!(
            "time scale {} must be a number above 0 (and at most 1e6)",
            config.time_scale
        ))
        .into());
    }
    config
        .dmm
        .validate()
        .map_err(|e| BadInput(format!("simulated multimeter: {e}")))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let prologix_tcp = args.link.as_deref() == Some("prologix-tcp");
    let plan = args
        .config
        .as_ref()
        .map_or("PLAN".to_string(), |p| p.display().to_string());
    runtime.block_on(serve(
        config,
        specs,
        args.table_tcp,
        args.chamber_tcp,
        prologix_tcp,
        plan,
    ))
}

/// Reads a bench TOML or a plan TOML (see [`SimArgs::config`]).
fn load_config(path: &Path) -> Result<BenchConfig> {
    let shown = path.display();
    let src =
        std::fs::read_to_string(path).map_err(|e| BadInput(format!("cannot read {shown}: {e}")))?;
    let table: toml::Table = toml::from_str(&src)
        .map_err(|e| BadInput(format!("{shown}: not TOML: {}", one_line(&e.to_string()))))?;
    if table.contains_key("plan") || table.contains_key("simulation") {
        let plan = gyrocal_files::Plan::from_toml_str(&src, path)
            .map_err(|e| BadInput(one_line(&e.to_string())))?;
        Ok(gyrocal_sim::from_plan::bench_config(&plan))
    } else {
        toml::from_str::<BenchConfig>(&src).map_err(|e| {
            BadInput(format!(
                "{shown}: not a bench configuration: {}",
                one_line(&e.to_string())
            ))
            .into()
        })
    }
}

fn one_line(s: &str) -> String {
    s.split('\n')
        .map(str::trim_end)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Prints one JSON line on stdout and flushes it.
fn emit(value: &Value) -> Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{value}").context("writing to stdout")?;
    out.flush().context("flushing stdout")
}

async fn serve(
    config: BenchConfig,
    specs: Vec<FaultSpec>,
    table_tcp: Option<u16>,
    chamber_tcp: Option<u16>,
    prologix_tcp: bool,
    plan: String,
) -> Result<()> {
    if config.dmm_model.truevolt().is_some() {
        return serve_lan(config, specs, table_tcp, chamber_tcp, plan).await;
    }
    let (table_dev, table_slave, table_path) =
        gyrocal_link::pseudo_terminal().context("creating the table's pseudo-terminal")?;
    let listener = match table_tcp {
        Some(port) => Some(
            tokio::net::TcpListener::bind(("127.0.0.1", port))
                .await
                .with_context(|| format!("listening on 127.0.0.1:{port}"))?,
        ),
        None => None,
    };
    // the signal handlers exist before anyone is told the bench is up
    let mut sigint = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt())
        .context("installing the SIGINT handler")?;
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .context("installing the SIGTERM handler")?;
    let mut sigusr1 = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::user_defined1())
        .context("installing the SIGUSR1 handler")?;

    let (seed, time_scale, wire) = (config.seed, config.time_scale, config.table_wire);
    let prologix = matches!(config.dmm_link, gyrocal_sim::bench::DmmLink::Prologix(_));
    // the meter's end: a pseudo-terminal, or (GPIB-ETHERNET) a TCP port bridged to the
    // simulated controller, so a client may disconnect and connect again
    let (bench, dmm_shown, dmm_port, dmm_slave, bridge) = if prologix_tcp {
        let (ours, theirs) = tokio::io::duplex(1 << 16);
        let listener = tokio::net::TcpListener::bind(("127.0.0.1", 0))
            .await
            .context("listening for the Prologix GPIB-ETHERNET clients")?;
        let addr = listener
            .local_addr()
            .context("reading the TCP port's address")?;
        let bench = Bench::spawn_on(config, theirs, table_dev);
        let bridge = tokio::spawn(bridge_clients(listener, ours));
        (
            bench,
            format!("tcp://{addr}"),
            format!("prologix-tcp://{addr}?addr=22"),
            None,
            Some(bridge),
        )
    } else {
        let (dmm_dev, dmm_slave, dmm_path) =
            gyrocal_link::pseudo_terminal().context("creating the multimeter's pseudo-terminal")?;
        let shown = dmm_path;
        let port = if prologix {
            format!("prologix:{shown}?addr=22")
        } else {
            shown.clone()
        };
        let bench = Bench::spawn_on(config, dmm_dev, table_dev);
        (bench, shown, port, Some(dmm_slave), None)
    };
    let mut schedule = faults::schedule(&specs, &bench, time_scale);

    let mut hello = hello_line(
        &dmm_shown,
        &dmm_port,
        &table_path,
        seed,
        time_scale,
        &bench,
        &specs,
    );
    let acceptor = serve_table_tcp(listener, &bench, wire, &mut hello)?;
    let chamber = serve_chamber(&bench, chamber_tcp, &mut hello).await?;
    emit(&hello)?;
    tell_operator(&hello, &plan);
    tracing::info!(dmm = %dmm_port, table = %table_path, "simulated bench serving");

    let signal = until_stopped(&bench, &mut sigint, &mut sigterm, &mut sigusr1).await?;
    tracing::info!("{signal}: stopping the simulated bench");
    schedule.stop();
    emit(&final_state(signal, &bench, &schedule))?;

    if let Some(a) = acceptor {
        a.abort();
    }
    if let Some(b) = bridge {
        b.abort();
    }
    chamber.stop();
    let BenchHandle { table, dmm, .. } = bench;
    table.shutdown();
    let _ = tokio::time::timeout(Duration::from_secs(1), dmm.stop()).await;
    // the slave sides were kept open so clients could come and go; now they may close
    drop((dmm_slave, table_slave));
    Ok(())
}

/// The first JSON line: where the bench serves, its seed, time scale, truth and faults.
fn hello_line(
    dmm: &str,
    dmm_port: &str,
    table: &str,
    seed: u64,
    time_scale: f64,
    bench: &BenchHandle,
    specs: &[FaultSpec],
) -> Value {
    json!({
        "dmm": dmm,
        "dmm_port": dmm_port,
        "table": table,
        "pid": std::process::id(),
        "seed": seed,
        "time_scale": time_scale,
        "truth": bench.truth,
        "faults": specs.iter().map(ToString::to_string).collect::<Vec<_>>(),
    })
}

/// Serves the table on `listener` too, when there is one (every client gets the same table),
/// and says where in `hello`.
fn serve_table_tcp(
    listener: Option<tokio::net::TcpListener>,
    bench: &BenchHandle,
    wire: gyrocal_sim::bench::TableWire,
    hello: &mut Value,
) -> Result<Option<tokio::task::JoinHandle<()>>> {
    let Some(listener) = listener else {
        return Ok(None);
    };
    let addr = listener
        .local_addr()
        .context("reading the TCP port's address")?;
    hello["table_tcp"] = json!(format!("tcp://{addr}"));
    let table = bench.table.clone();
    Ok(Some(tokio::spawn(async move {
        loop {
            match listener.accept().await {
                Ok((sock, peer)) => {
                    tracing::info!(%peer, "table client connected over TCP");
                    let _ = sock.set_nodelay(true);
                    table.serve_wire(sock, wire);
                }
                Err(e) => {
                    tracing::warn!(error = %e, "accepting a table client failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    })))
}

/// What serves the chamber: a TCP acceptor, or a pseudo-terminal's slave side kept open.
#[derive(Default)]
struct ChamberServing {
    acceptor: Option<tokio::task::JoinHandle<()>>,
    // the slave side, kept open so a client may close the port and open it again
    slave: Option<Box<dyn Send>>,
}

impl ChamberServing {
    fn stop(self) {
        if let Some(a) = self.acceptor {
            a.abort();
        }
        drop(self.slave);
    }
}

/// Serves the bench's chamber, if it has one: Modbus TCP on 127.0.0.1:`tcp` (every client
/// the same controller), else its wire on a pseudo-terminal; says where in `hello`.
async fn serve_chamber(
    bench: &BenchHandle,
    tcp: Option<u16>,
    hello: &mut Value,
) -> Result<ChamberServing> {
    let Some(chamber) = bench.chamber.clone() else {
        return Ok(ChamberServing::default());
    };
    hello["chamber_model"] = serde_json::to_value(chamber.config().model)?;
    if let Some(port) = tcp {
        let listener = tokio::net::TcpListener::bind(("127.0.0.1", port))
            .await
            .with_context(|| format!("listening for the chamber on 127.0.0.1:{port}"))?;
        let addr = listener
            .local_addr()
            .context("reading the chamber's TCP address")?;
        hello["chamber"] = json!(format!("tcp://{addr}"));
        let acceptor = tokio::spawn(async move {
            loop {
                match listener.accept().await {
                    Ok((sock, peer)) => {
                        tracing::info!(%peer, "chamber client connected over Modbus TCP");
                        let _ = sock.set_nodelay(true);
                        chamber.serve_tcp(sock);
                    }
                    Err(e) => {
                        tracing::warn!(error = %e, "accepting a chamber client failed");
                        tokio::time::sleep(Duration::from_millis(50)).await;
                    }
                }
            }
        });
        return Ok(ChamberServing {
            acceptor: Some(acceptor),
            slave: None,
        });
    }
    let (dev, slave, path) =
        gyrocal_link::pseudo_terminal().context("creating the chamber's pseudo-terminal")?;
    chamber.serve(dev);
    hello["chamber"] = json!(path);
    Ok(ChamberServing {
        acceptor: None,
        slave: Some(Box::new(slave)),
    })
}

/// The human line (on stderr; stdout stays one JSON document per line for scripts): the
/// command that runs a plan against this bench.
fn tell_operator(hello: &Value, plan: &str) {
    let dmm = hello["dmm_port"].as_str().unwrap_or("?");
    let table = hello["table"].as_str().unwrap_or("?");
    eprintln!(
        "simulated bench ready (Ctrl-C to stop it). Run a plan against it with:\n  gyrocal run {plan} --dmm-port {dmm} --table-port {table}"
    );
}

/// Hands the simulated controller's byte stream to the newest TCP client (a client that
/// reconnects takes over, as with a real GPIB-ETHERNET controller, which serves one at a time).
async fn bridge_clients(listener: tokio::net::TcpListener, end: tokio::io::DuplexStream) {
    let end = std::sync::Arc::new(tokio::sync::Mutex::new(end));
    let mut current: Option<tokio::task::JoinHandle<()>> = None;
    loop {
        match listener.accept().await {
            Ok((mut sock, peer)) => {
                tracing::info!(%peer, "Prologix client connected over TCP");
                let _ = sock.set_nodelay(true);
                if let Some(previous) = current.take() {
                    previous.abort();
                    let _ = previous.await;
                }
                let end = end.clone();
                current = Some(tokio::spawn(async move {
                    let mut end = end.lock().await;
                    // copy both ways until the client goes, never shutting the controller's
                    // side down (copy_bidirectional would: the next client would find it closed)
                    let (mut from_client, mut to_client) = sock.split();
                    let (mut from_bench, mut to_bench) = tokio::io::split(&mut *end);
                    tokio::select! {
                        _ = tokio::io::copy(&mut from_client, &mut to_bench) => {}
                        _ = tokio::io::copy(&mut from_bench, &mut to_client) => {}
                    }
                }));
            }
            Err(e) => {
                tracing::warn!(error = %e, "accepting a Prologix client failed");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
}

fn final_state(signal: &str, bench: &BenchHandle, schedule: &FaultSchedule) -> Value {
    let t = &bench.table;
    let now = tokio::time::Instant::now();
    let d = bench.dmm.stats();
    let mut out = json!({
        "exit": signal,
        "table": {
            "mode": format!("{:?}", t.mode()).to_ascii_uppercase(),
            "demanded_rate": t.demanded_rate(),
            "actual_rate": t.actual_rate(now),
            "stopped": t.is_stopped(),
            "interlock_closed": t.interlock_closed(),
            "fault": t.fault(),
            "silent": t.is_silent(),
            "demands_seen": t.demands_seen(),
        },
        "dmm": {
            "readings_taken": d.readings_taken,
            "commands_seen": d.commands_seen,
            "lines_seen": d.lines_seen,
            "queries_answered": d.queries_answered,
            "device_clears": d.device_clears,
            "errors_raised": d.errors_raised,
            "remote": d.remote,
            "stopped": d.stopped,
            "power_cycles": d.power_cycles,
            "nplc": d.nplc,
            "late_replies": d.late_replies,
        },
        "faults": schedule.status(bench).iter().map(|s| json!({
            "spec": s.spec,
            "fired": s.fired,
        })).collect::<Vec<_>>(),
    });
    if let Some(c) = &bench.chamber {
        let temps = c.temperatures(now);
        out["chamber"] = json!({
            "setpoint_c": c.setpoint_c(),
            "air_c": temps.air_c,
            "case_c": temps.case_c,
            "inside_c": temps.inside_c,
            "alarms": c.alarms().iter().map(|a| a.name()).collect::<Vec<_>>(),
            "requests_seen": c.requests_seen(),
        });
    }
    out
}

/// Serves until SIGINT or SIGTERM (which it returns); meanwhile each SIGUSR1 is the operator
/// at the simulated chamber's panel pressing its alarm reset: the latched alarms are cleared
/// and said in a JSON line `{"chamber_panel": "alarms reset", "cleared": [...]}` (a real
/// chamber's alarm is cleared at its panel, which a run never does on its own: the Watlow
/// driver has no confirmed reset register; without this, nothing could clear the simulator's
/// latched alarm and a run stopped by one could never be resumed against it).
async fn until_stopped(
    bench: &BenchHandle,
    sigint: &mut tokio::signal::unix::Signal,
    sigterm: &mut tokio::signal::unix::Signal,
    sigusr1: &mut tokio::signal::unix::Signal,
) -> Result<&'static str> {
    loop {
        tokio::select! {
            _ = sigint.recv() => return Ok("SIGINT"),
            _ = sigterm.recv() => return Ok("SIGTERM"),
            _ = sigusr1.recv() => {
                let cleared: Vec<&str> = bench.chamber.as_ref().map_or_else(Vec::new, |c| {
                    let latched = c.alarms();
                    c.reset_alarms();
                    latched.iter().map(|a| a.name()).collect()
                });
                tracing::info!(?cleared, "SIGUSR1: the chamber's alarms reset at its panel");
                emit(&json!({ "chamber_panel": "alarms reset", "cleared": cleared }))?;
            }
        }
    }
}

/// `gyrocal sim` with a Truevolt: the meter on tcp://127.0.0.1:P (every accepted connection
/// handed to the instrument, the newest served), the table on a pseudo-terminal (and TCP when
/// asked). Same JSON contract, with "dmm" the meter's tcp:// address.
async fn serve_lan(
    config: BenchConfig,
    specs: Vec<FaultSpec>,
    table_tcp: Option<u16>,
    chamber_tcp: Option<u16>,
    plan: String,
) -> Result<()> {
    let (table_dev, table_slave, table_path) =
        gyrocal_link::pseudo_terminal().context("creating the table's pseudo-terminal")?;
    let dmm_listener = tokio::net::TcpListener::bind(("127.0.0.1", 0))
        .await
        .context("listening for the multimeter's SCPI socket on 127.0.0.1")?;
    let dmm_addr = dmm_listener
        .local_addr()
        .context("reading the multimeter's TCP address")?;
    let table_listener = match table_tcp {
        Some(port) => Some(
            tokio::net::TcpListener::bind(("127.0.0.1", port))
                .await
                .with_context(|| format!("listening on 127.0.0.1:{port}"))?,
        ),
        None => None,
    };
    let mut sigint = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::interrupt())
        .context("installing the SIGINT handler")?;
    let mut sigterm = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .context("installing the SIGTERM handler")?;
    let mut sigusr1 = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::user_defined1())
        .context("installing the SIGUSR1 handler")?;
    let (seed, time_scale, wire) = (config.seed, config.time_scale, config.table_wire);
    // the meter's first "connection" is a pipe nobody holds: clients come over TCP
    let (_unused, dmm_dev) = tokio::io::duplex(16);
    drop(_unused);
    let bench = Bench::spawn_on(config, dmm_dev, table_dev);
    let mut schedule = faults::schedule(&specs, &bench, time_scale);
    let Some(lan) = bench.lan.clone() else {
        anyhow::bail!("the simulated bench has no LAN meter");
    };
    let dmm_acceptor = tokio::spawn(async move {
        loop {
            match dmm_listener.accept().await {
                Ok((sock, peer)) => {
                    tracing::info!(%peer, "multimeter client connected over TCP");
                    let _ = sock.set_nodelay(true);
                    if !lan.attach(Box::new(sock)) {
                        break;
                    }
                }
                Err(e) => {
                    tracing::warn!(error = %e, "accepting a multimeter client failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    });
    let dmm_shown = format!("tcp://{dmm_addr}");
    let mut hello = hello_line(
        &dmm_shown,
        &dmm_shown,
        &table_path,
        seed,
        time_scale,
        &bench,
        &specs,
    );
    let table_acceptor = serve_table_tcp(table_listener, &bench, wire, &mut hello)?;
    let chamber = serve_chamber(&bench, chamber_tcp, &mut hello).await?;
    emit(&hello)?;
    tell_operator(&hello, &plan);
    let signal = until_stopped(&bench, &mut sigint, &mut sigterm, &mut sigusr1).await?;
    schedule.stop();
    emit(&final_state(signal, &bench, &schedule))?;
    dmm_acceptor.abort();
    if let Some(a) = table_acceptor {
        a.abort();
    }
    chamber.stop();
    let BenchHandle { table, dmm, .. } = bench;
    table.shutdown();
    let _ = tokio::time::timeout(Duration::from_secs(1), dmm.stop()).await;
    drop(table_slave);
    Ok(())
}
