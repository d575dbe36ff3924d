//! The power cycle and the LOCAL modes, over an in-memory pipe in virtual time.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use gyrocal_link::{ErrorKind, StreamTransport, Transport, memory_pair};
use tokio::io::DuplexStream;
use tokio::time::Instant;

use super::{DmmConfig, DmmHandle, Fault, LocalMode, SimDmm};
use crate::signal::Constant;

const T: Option<Duration> = Some(Duration::from_secs(3));
const IDN: &str = "HEWLETT-PACKARD,34401A,0,11-5-2";

fn meter(cfg: DmmConfig) -> (StreamTransport<DuplexStream>, DmmHandle) {
    let (link, dev) = memory_pair("raw");
    let cfg = DmmConfig {
        noise_v: 0.0,
        ..cfg
    };
    (link, SimDmm::spawn(dev, cfg, Box::new(Constant(1.5)), 3))
}

async fn q(t: &mut StreamTransport<DuplexStream>, line: &str) -> String {
    t.send_line(line).await.unwrap();
    t.read_line(T).await.unwrap()
}

async fn silent(t: &mut StreamTransport<DuplexStream>, line: &str) {
    t.send_line(line).await.unwrap();
    let e = t.read_line(T).await.unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Timeout, "{line}: {e}");
}

/// A meter in remote, configured away from the power-on settings, with readings in memory.
async fn configured(cfg: DmmConfig) -> (StreamTransport<DuplexStream>, DmmHandle) {
    let (mut t, h) = meter(cfg);
    assert_eq!(q(&mut t, "SYST:REM;*CLS;*OPC?").await, "1");
    t.send_line("CONF:VOLT:DC 10;:VOLT:DC:NPLC 1;:ZERO:AUTO OFF;:SAMP:COUN 5")
        .await
        .unwrap();
    assert_eq!(q(&mut t, "INIT;*OPC?").await, "1");
    assert_eq!(q(&mut t, "DATA:POIN?").await, "+5");
    assert_eq!(q(&mut t, "*ESR?").await, "+0");
    let st = h.stats();
    assert_eq!((st.nplc, st.memory_points, st.remote), (1.0, 5, true));
    (t, h)
}

#[tokio::test(start_paused = true)]
async fn power_cycle_comes_back_in_local_with_power_on_state() {
    let (mut t, h) = configured(DmmConfig::default()).await;
    // an error left in the queue, to see it go
    t.send_line("BOGUS").await.unwrap();
    assert_eq!(q(&mut t, "*OPC?").await, "1");
    let t0 = Instant::now();
    h.inject(Fault::PowerCycle { off_s: None });
    tokio::time::sleep(Duration::from_millis(10)).await;
    let st = h.stats();
    assert!(!st.powered);
    // dead: a query (and a device clear) sent now is lost, even once the meter is back
    t.write_raw(&[0x03]).await.unwrap();
    silent(&mut t, "SYST:REM;*IDN?").await;
    tokio::time::sleep_until(t0 + Duration::from_millis(5_010)).await;
    let st = h.stats();
    assert!(st.powered);
    assert_eq!(st.power_cycles, 1);
    assert!(!st.remote, "power-on is LOCAL");
    assert_eq!(st.nplc, 10.0, "power-on NPLC");
    assert_eq!(st.memory_points, 0);
    assert!(st.error_queue.is_empty(), "{:?}", st.error_queue);
    // LOCAL, default mode: refused with 550, not answered
    silent(&mut t, "*IDN?").await;
    assert_eq!(q(&mut t, "SYST:REM;*IDN?").await, IDN);
    assert_eq!(
        q(&mut t, "SYST:ERR?").await,
        "+550,\"Command not allowed in local\""
    );
    assert_eq!(q(&mut t, "SYST:ERR?").await, "+0,\"No error\"");
    // the power-on state
    assert_eq!(q(&mut t, "VOLT:DC:NPLC?").await, "+1.00000000E+01");
    assert_eq!(q(&mut t, "ZERO:AUTO?").await, "1");
    assert_eq!(q(&mut t, "VOLT:DC:RANG:AUTO?").await, "1");
    assert_eq!(q(&mut t, "SAMP:COUN?").await, "+1");
    assert_eq!(q(&mut t, "DATA:POIN?").await, "+0");
    // the Power On bit, read once
    assert_eq!(q(&mut t, "*ESR?").await, "+128");
    assert_eq!(q(&mut t, "*ESR?").await, "+0");
    // FETC? with the memory empty: no reply, -230
    silent(&mut t, "FETC?").await;
    t.write_raw(&[0x03]).await.unwrap();
    assert_eq!(q(&mut t, "SYST:ERR?").await, "-230,\"Data stale\"");
    h.stop().await;
}

#[tokio::test(start_paused = true)]
async fn power_cycle_armed_at_a_reading_kills_the_stream_there() {
    let (mut t, h) = configured(DmmConfig::default()).await;
    let before = h.readings_taken();
    h.inject_at_reading(before + 10, Fault::PowerCycle { off_s: Some(2.0) });
    t.send_line("SAMP:COUN 20;:READ?").await.unwrap();
    // nine readings come, then nothing
    let mut got = 0;
    loop {
        match t.read_field(b',', Some(Duration::from_secs(1))).await {
            Ok(f) => {
                assert!(!f.end_of_line);
                got += 1;
            }
            Err(e) => {
                assert_eq!(e.kind(), ErrorKind::Timeout);
                break;
            }
        }
    }
    // the ninth may still be in the buffer without its comma
    assert!((8..=9).contains(&got), "{got}");
    assert_eq!(h.readings_taken(), before + 9);
    tokio::time::sleep(Duration::from_secs(2)).await;
    t.discard_input().await.unwrap();
    let st = h.stats();
    assert_eq!((st.power_cycles, st.remote, st.nplc), (1, false, 10.0));
    assert_eq!(q(&mut t, "SYST:REM;*IDN?").await, IDN);
    h.stop().await;
}

#[tokio::test(start_paused = true)]
async fn local_modes() {
    // ignore: nothing done, nothing queued
    let (mut t, h) = meter(DmmConfig {
        local_mode: LocalMode::Ignore,
        ..DmmConfig::default()
    });
    silent(&mut t, "*IDN?").await;
    t.send_line("VOLT:DC:NPLC 1").await.unwrap();
    assert_eq!(q(&mut t, "SYST:REM;*IDN?").await, IDN);
    assert_eq!(q(&mut t, "SYST:ERR?").await, "+0,\"No error\"");
    assert_eq!(q(&mut t, "VOLT:DC:NPLC?").await, "+1.00000000E+01");
    h.stop().await;
    // obey: answered and executed in LOCAL; a power cycle still shows in *ESR?
    let (mut t, h) = meter(DmmConfig {
        local_mode: LocalMode::Obey,
        ..DmmConfig::default()
    });
    assert_eq!(q(&mut t, "*IDN?").await, IDN);
    assert_eq!(q(&mut t, "*ESR?").await, "+128", "power-on at start");
    assert!(!h.stats().remote);
    h.inject(Fault::PowerCycle { off_s: Some(1.0) });
    tokio::time::sleep(Duration::from_millis(1_010)).await;
    assert_eq!(q(&mut t, "*ESR?").await, "+128");
    assert_eq!(h.stats().power_cycles, 1);
    h.stop().await;
}

#[test]
fn config_fields() {
    let c: DmmConfig = toml::from_str("local_mode = \"ignore\"\npower_off_s = 2.5").unwrap();
    assert_eq!((c.local_mode, c.power_off_s), (LocalMode::Ignore, 2.5));
    assert!(toml::from_str::<DmmConfig>("local_mode = \"sometimes\"").is_err());
    let bad = DmmConfig {
        power_off_s: -1.0,
        ..DmmConfig::default()
    };
    assert!(bad.validate().unwrap_err().contains("power_off_s"));
    let f: Fault = toml::from_str("kind = \"power_cycle\"").unwrap();
    assert_eq!(f, Fault::PowerCycle { off_s: None });
}
