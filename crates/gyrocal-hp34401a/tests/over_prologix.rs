//! The driver over a [`PrologixTransport`] against the simulated Prologix controller and the
//! simulated 34401A in GPIB mode, over an in-memory pipe, in virtual time.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use gyrocal_hp34401a::{DriverOptions, Hp34401a, Strategy};
use gyrocal_link::{
    DynStream, LinkOptions, PrologixOptions, PrologixTransport, StreamTransport, Transport,
    memory_pair,
};
use gyrocal_sim::dmm::{DmmConfig, DmmHandle, Fault};
use gyrocal_sim::prologix::{PrologixConfig, PrologixHandle, spawn_gpib_meter};
use gyrocal_sim::signal::Constant;
use tokio::time::Instant;

mod common;
use common::{VOLTS, nplc1};

type Dmm = Hp34401a<PrologixTransport<StreamTransport<DynStream>>>;

async fn bench() -> (Dmm, PrologixHandle, DmmHandle) {
    let (link, dev) = memory_pair("sim-prologix");
    let (ctl, meter) = spawn_gpib_meter(
        dev,
        PrologixConfig::default(),
        DmmConfig::default(),
        Box::new(Constant(VOLTS)),
        7,
    );
    let link = PrologixTransport::open(link.boxed(), PrologixOptions::default())
        .await
        .unwrap();
    assert_eq!(link.version(), "Prologix GPIB-USB Controller version 6.107");
    let mut dmm = Hp34401a::new(link, DriverOptions::default());
    let id = dmm.connect().await.unwrap();
    assert_eq!(id.raw, "HEWLETT-PACKARD,34401A,0,11-5-2");
    dmm.configure(&nplc1()).await.unwrap();
    (dmm, ctl, meter)
}

fn check(volts: &[f64], n: usize) {
    assert_eq!(volts.len(), n);
    for v in volts {
        assert!((v - 1.234_567).abs() < 1e-5, "{v}");
    }
}

#[tokio::test(start_paused = true)]
async fn connect_configure_and_500_readings_stream_and_memory() {
    let (mut dmm, ctl, meter) = bench().await;
    let st = ctl.stats();
    assert_eq!(
        &st.commands[..10],
        [
            "++savecfg 0",
            "++mode 1",
            "++ifc",
            "++addr 22",
            "++auto 0",
            "++eoi 1",
            "++eos 2",
            "++eot_enable 0",
            "++read_tmo_ms 1000",
            "++ver"
        ]
    );
    assert!(!st.commands.iter().any(|c| c == "++auto 1"));
    // device clear at connect went over the bus as SDC; no SYST:REM was needed or sent
    assert_eq!(st.clears, 1);
    assert_eq!(meter.stats().device_clears, 1);
    assert!(meter.stats().error_queue.is_empty());

    let t0 = Instant::now();
    let acq = dmm.acquire(500, Strategy::Stream).await.unwrap();
    let stream = t0.elapsed().as_secs_f64();
    check(&acq.volts(), 500);
    assert_eq!(acq.retries, 0);
    // GPIB does not limit the stream: arm + 500 readings of 41.5 ms
    let doc = 0.020 + 500.0 * 0.0415;
    assert!(
        (stream - doc).abs() / doc < 0.02,
        "stream {stream} vs {doc}"
    );

    let t0 = Instant::now();
    let acq = dmm.acquire(500, Strategy::Memory).await.unwrap();
    let memory = t0.elapsed().as_secs_f64();
    check(&acq.volts(), 500);
    assert_eq!(acq.retries, 0);
    assert!(memory < stream * 1.2, "memory {memory} vs stream {stream}");
    // the long INIT;*OPC? waits were read again after the controller's read timeout
    assert!(ctl.stats().read_timeouts > 0);
    assert_eq!(ctl.stats().unknown, 0);
    // nothing provoked a query error on the way
    let errs = dmm.drain_errors().await.unwrap();
    assert!(errs.is_empty(), "{errs:?}");
    let link = dmm.close().await.unwrap();
    assert!(!link.needs_remote_command());
}

#[tokio::test(start_paused = true)]
async fn device_clear_recovers_after_a_garbled_reply() {
    for s in [Strategy::Stream, Strategy::Memory, Strategy::Poll] {
        recovers_from(Fault::Garble, s).await;
    }
}

#[tokio::test(start_paused = true)]
async fn device_clear_recovers_after_a_lost_or_truncated_reply() {
    for f in [Fault::NoReply, Fault::Truncate] {
        for s in [Strategy::Stream, Strategy::Memory, Strategy::Poll] {
            recovers_from(f.clone(), s).await;
        }
    }
}

async fn recovers_from(fault: Fault, s: Strategy) {
    {
        let (mut dmm, ctl, meter) = bench().await;
        meter.inject(fault.clone());
        let acq = dmm.acquire(40, s).await.unwrap();
        check(&acq.volts(), 40);
        assert_eq!(acq.retries, 1, "{fault:?} {s:?}");
        assert_eq!(
            ctl.stats().clears,
            2,
            "connect and one recovery ({fault:?} {s:?})"
        );
        assert_eq!(meter.stats().device_clears, 2, "{fault:?} {s:?}");
        // the recovery was a plain one: no re-establishing, no SYST:REM over GPIB
        assert_eq!(acq.reestablished(), 0, "{fault:?} {s:?}");
    }
}

/// Real time: a real TCP socket and a paused clock do not mix (the clock would jump past bytes
/// in flight), so the meter runs ten times faster instead.
#[tokio::test]
async fn open_accepts_prologix_tcp_port_strings() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let server = tokio::spawn(async move {
        let (sock, _) = listener.accept().await.unwrap();
        spawn_gpib_meter(
            sock,
            PrologixConfig {
                version: "Prologix GPIB-ETHERNET Controller version 01.06.06.00".into(),
                instrument_addr: 9,
                ..PrologixConfig::default()
            },
            DmmConfig {
                time_scale: 10.0,
                ..DmmConfig::default()
            },
            Box::new(Constant(VOLTS)),
            3,
        )
    });
    let link = gyrocal_link::open(
        &format!("prologix-tcp://127.0.0.1:{port}?addr=9"),
        &LinkOptions::default(),
    )
    .await
    .unwrap();
    let (_ctl, _meter) = server.await.unwrap();
    assert!(link.describe().contains("GPIB 9"), "{}", link.describe());
    assert!(!link.needs_remote_command());
    let mut dmm = Hp34401a::new(link, DriverOptions::default());
    dmm.connect().await.unwrap();
    dmm.configure(&nplc1()).await.unwrap();
    let acq = dmm.acquire(20, Strategy::Stream).await.unwrap();
    check(&acq.volts(), 20);
}
