//! The driver through the real serial code (a pseudo-terminal) and over TCP, against the
//! simulator in real time with a time scale (virtual time is unreliable over a pseudo-terminal).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use gyrocal_hp34401a::{AutoZero, DcvConfig, DriverOptions, Hp34401a, Strategy};
use gyrocal_link::{LinkOptions, Transport};
use gyrocal_sim::dmm::{DmmConfig, SimDmm};
use gyrocal_sim::signal::Constant;

fn fast_sim() -> DmmConfig {
    DmmConfig {
        time_scale: 20.0,
        noise_v: 0.0,
        ..DmmConfig::default()
    }
}

async fn exercise<T: Transport>(link: T) {
    let opts = DriverOptions {
        clear_settle: Duration::from_millis(20),
        ..DriverOptions::default()
    };
    let mut dmm = Hp34401a::new(link, opts);
    dmm.connect().await.unwrap();
    let cfg = DcvConfig {
        nplc: 1.0,
        autozero: AutoZero::On,
        range: Some(10.0),
        ..DcvConfig::default()
    };
    dmm.configure(&cfg).await.unwrap();
    for (n, s) in [
        (200, Strategy::Stream),
        (600, Strategy::Memory),
        (10, Strategy::Poll),
    ] {
        let acq = dmm.acquire(n, s).await.unwrap();
        assert_eq!(acq.readings.len(), n, "{s:?}");
        assert!(acq.volts().iter().all(|&v| v == 2.5), "{s:?}");
    }
    dmm.close().await.unwrap();
}

#[cfg(unix)]
#[tokio::test]
async fn pseudo_terminal_through_the_serial_code() {
    let (device, placeholder, path) = gyrocal_link::pseudo_terminal().unwrap();
    // the host side opens the path like a real port: 9600 8N2, DTR (ENOTTY tolerated), flush
    let link = gyrocal_link::open(&path, &LinkOptions::default())
        .await
        .unwrap();
    drop(placeholder);
    // the simulator side stays alive (and so the master) until the driver is done
    let sim = SimDmm::spawn(device, fast_sim(), Box::new(Constant(2.5)), 1);
    tokio::time::timeout(Duration::from_secs(60), exercise(link))
        .await
        .unwrap();
    assert_eq!(sim.readings_taken(), 810);
    sim.stop().await;
}

#[tokio::test]
async fn tcp_link() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let server = tokio::spawn(async move {
        let (sock, _) = listener.accept().await.unwrap();
        SimDmm::spawn(sock, fast_sim(), Box::new(Constant(2.5)), 1)
    });
    let link = gyrocal_link::open(&format!("tcp://{addr}"), &LinkOptions::default())
        .await
        .unwrap();
    assert_eq!(link.describe(), format!("tcp://{addr}"));
    let sim = server.await.unwrap();
    tokio::time::timeout(Duration::from_secs(60), exercise(link))
        .await
        .unwrap();
    sim.stop().await;
}

#[tokio::test]
async fn bad_baud_and_missing_port_are_io_errors() {
    let opts = LinkOptions {
        baud: 19200,
        ..LinkOptions::default()
    };
    let err = gyrocal_link::open("/dev/does-not-exist", &opts)
        .await
        .unwrap_err();
    assert_eq!(err.kind(), gyrocal_link::ErrorKind::Io);
    assert!(err.to_string().contains("19200"), "{err}");
    let err = gyrocal_link::open("/dev/does-not-exist", &LinkOptions::default())
        .await
        .unwrap_err();
    assert_eq!(err.kind(), gyrocal_link::ErrorKind::Io);
}
