//! The simulated 34401A's wire protocol, byte for byte, in virtual time.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use gyrocal_link::{ErrorKind, StreamTransport, Transport, memory_pair};
use gyrocal_sim::dmm::{DmmConfig, DmmHandle, SimDmm};
use gyrocal_sim::signal::Constant;
use tokio::io::DuplexStream;
use tokio::time::Instant;

const T: Option<Duration> = Some(Duration::from_secs(5));

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

async fn remote() -> (StreamTransport<DuplexStream>, DmmHandle) {
    let (mut t, h) = meter(DmmConfig::default());
    assert_eq!(q(&mut t, "SYST:REM;*OPC?").await, "1");
    (t, h)
}

#[tokio::test(start_paused = true)]
async fn dmm_strict_remote_first() {
    let (mut t, h) = meter(DmmConfig::default());
    t.send_line("*IDN?").await.unwrap();
    assert_eq!(t.read_line(T).await.unwrap_err().kind(), ErrorKind::Timeout);
    assert_eq!(
        q(&mut t, "SYST:REM;*IDN?").await,
        "HEWLETT-PACKARD,34401A,0,11-5-2"
    );
    assert_eq!(
        q(&mut t, "SYST:ERR?").await,
        "+550,\"Command not allowed in local\""
    );
    assert_eq!(q(&mut t, "SYST:ERR?").await, "+0,\"No error\"");
    // lenient when asked
    let (mut t2, _h2) = meter(DmmConfig {
        strict_remote: false,
        ..DmmConfig::default()
    });
    assert_eq!(q(&mut t2, "*IDN?").await, "HEWLETT-PACKARD,34401A,0,11-5-2");
    h.stop().await;
}

#[tokio::test(start_paused = true)]
async fn dmm_syntax_forms_chaining_and_several_queries() {
    let (mut t, _h) = remote().await;
    assert_eq!(q(&mut t, "syst:err?").await, "+0,\"No error\"");
    t.send_line("SENSE:VOLTAGE:DC:NPLCYCLES 1;:trig:sour bus;del 0.5;COUN 3")
        .await
        .unwrap();
    assert_eq!(
        q(&mut t, "VOLT:NPLC?;:TRIG:SOUR?;DEL?;COUN?;:ZERO:AUTO?").await,
        "+1.00000000E+00;BUS;+5.00000000E-01;+3;1"
    );
    t.send_line("VOLTAG:DC:NPLC 1").await.unwrap();
    t.send_line("*WAI").await.unwrap();
    assert_eq!(
        q(&mut t, "SYST:ERR?;ERR?;ERR?").await,
        "-113,\"Undefined header\";-113,\"Undefined header\";+0,\"No error\""
    );
    assert_eq!(q(&mut t, "SAMP:COUN 500;COUN?").await, "+500");
}

#[tokio::test(start_paused = true)]
async fn dmm_only_five_nplc_values() {
    let (mut t, _h) = remote().await;
    for v in ["0.02", "0.2", "1", "10", "100"] {
        t.send_line(&format!("VOLT:DC:NPLC {v}")).await.unwrap();
    }
    assert_eq!(q(&mut t, "SYST:ERR?").await, "+0,\"No error\"");
    t.send_line("VOLT:DC:NPLC 2").await.unwrap();
    assert_eq!(q(&mut t, "SYST:ERR?").await, "-222,\"Data out of range\"");
    assert_eq!(q(&mut t, "VOLT:DC:NPLC?").await, "+1.00000000E+02");
}

#[tokio::test(start_paused = true)]
async fn dmm_read_streams_exact_format_with_crlf() {
    let (mut t, _h) = remote().await;
    t.send_line("VOLT:NPLC 1;:SAMP:COUN 3").await.unwrap();
    t.send_line("READ?").await.unwrap();
    let line = t.read_line(T).await.unwrap();
    assert_eq!(line, "+1.50000000E+00,+1.50000000E+00,+1.50000000E+00");
    // the CR is stripped by the transport; check it is on the wire with a raw read
    let (mut link, dev) = memory_pair("raw2");
    let h = SimDmm::spawn(
        dev,
        DmmConfig {
            noise_v: 0.0,
            strict_remote: false,
            ..DmmConfig::default()
        },
        Box::new(Constant(-0.25)),
        1,
    );
    link.send_line("READ?").await.unwrap();
    let f = link.read_field(b'\r', T).await.unwrap();
    assert_eq!(f.text, "-2.50000000E-01");
    assert!(!f.end_of_line);
    assert_eq!(link.read_line(T).await.unwrap(), "");
    h.stop().await;
}

#[tokio::test(start_paused = true)]
async fn dmm_memory_limit_and_deaf_after_init() {
    let (mut t, h) = remote().await;
    t.send_line("VOLT:NPLC 10;:ZERO:AUTO OFF;:SAMP:COUN 513")
        .await
        .unwrap();
    t.send_line("INIT").await.unwrap();
    assert_eq!(q(&mut t, "SYST:ERR?").await, "+531,\"Insufficient memory\"");
    t.send_line("SAMP:COUN 10").await.unwrap();
    let t0 = Instant::now();
    // deaf until the burst ends: *IDN? is answered only after 20 ms + 10 x 201.5 ms
    t.send_line("INIT").await.unwrap();
    t.send_line("*IDN?").await.unwrap();
    t.read_line(T).await.unwrap();
    let waited = t0.elapsed().as_secs_f64();
    assert!(waited > 2.035 && waited < 2.2, "{waited}");
    assert_eq!(q(&mut t, "DATA:POIN?").await, "+10");
    let fetched = q(&mut t, "FETC?").await;
    assert_eq!(fetched.split(',').count(), 10);
    assert_eq!(h.readings_taken(), 10);
    assert_eq!(q(&mut t, "SYST:ERR?").await, "+0,\"No error\"");
}

#[tokio::test(start_paused = true)]
async fn dmm_init_opc_answers_at_end_of_burst() {
    let (mut t, _h) = remote().await;
    t.send_line("VOLT:NPLC 1;:SAMP:COUN 100").await.unwrap();
    let t0 = Instant::now();
    assert_eq!(q(&mut t, "INIT;*OPC?").await, "1");
    let s = t0.elapsed().as_secs_f64();
    // plus the commands' and the reply's characters on the wire
    assert!(s > 0.020 + 100.0 * 0.0415 && s < 4.25, "{s}");
}

#[tokio::test(start_paused = true)]
async fn dmm_piled_up_queries_raise_410_or_420() {
    let (mut t, h) = remote().await;
    // a second query before the first reply has been read: the first reply is lost
    t.send_line("*IDN?").await.unwrap();
    t.send_line("*IDN?").await.unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(
        t.read_line(T).await.unwrap(),
        "HEWLETT-PACKARD,34401A,0,11-5-2"
    );
    assert_eq!(
        t.read_line(Some(Duration::from_millis(500)))
            .await
            .unwrap_err()
            .kind(),
        ErrorKind::Timeout
    );
    assert_eq!(q(&mut t, "SYST:ERR?").await, "-420,\"Query UNTERMINATED\"");
    // a new line while a long reply is on the wire interrupts it
    t.send_line("VOLT:NPLC 1;:SAMP:COUN 50").await.unwrap();
    t.send_line("READ?").await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    t.send_line("SYST:ERR?").await.unwrap();
    // the host sees the partial stream run into the next reply: a mixed line
    let mixed = t.read_line(T).await.unwrap();
    assert!(mixed.starts_with("+1.50000000E+00,"), "{mixed}");
    assert!(mixed.ends_with("-410,\"Query INTERRUPTED\""), "{mixed}");
    assert_eq!(q(&mut t, "SYST:ERR?").await, "+0,\"No error\"");
    let st = h.stats();
    assert!(st.errors_raised >= 2, "{st:?}");
    assert!(st.readings_taken < 50, "the READ? was aborted: {st:?}");
}

#[tokio::test(start_paused = true)]
async fn dmm_error_queue_holds_20_then_overflows() {
    let (mut t, _h) = remote().await;
    for _ in 0..5 {
        t.send_line("BAD;BAD;BAD;BAD;BAD").await.unwrap();
    }
    let mut got = Vec::new();
    loop {
        let e = q(&mut t, "SYST:ERR?").await;
        if e.starts_with("+0") {
            break;
        }
        got.push(e);
    }
    assert_eq!(got.len(), 20);
    assert!(got[..19].iter().all(|e| e == "-113,\"Undefined header\""));
    assert_eq!(got[19], "-350,\"Queue overflow\"");
}

#[tokio::test(start_paused = true)]
async fn dmm_device_clear_aborts_and_keeps_config_and_errors() {
    let (mut t, h) = remote().await;
    t.send_line("BAD").await.unwrap();
    t.send_line("VOLT:NPLC 10;:SAMP:COUN 100").await.unwrap();
    t.send_line("READ?").await.unwrap();
    tokio::time::sleep(Duration::from_secs(2)).await;
    t.write_raw(&[0x03]).await.unwrap();
    tokio::time::sleep(Duration::from_millis(50)).await;
    t.discard_input().await.unwrap();
    let taken = h.readings_taken();
    assert!(taken < 10, "{taken}");
    assert_eq!(q(&mut t, "SAMP:COUN?").await, "+100");
    assert_eq!(q(&mut t, "SYST:ERR?").await, "-113,\"Undefined header\"");
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert_eq!(h.readings_taken(), taken, "no measuring after the clear");
    assert_eq!(h.stats().device_clears, 1);
}

#[tokio::test(start_paused = true)]
async fn dmm_output_is_paced_by_the_wire() {
    let (mut t, _h) = meter(DmmConfig {
        strict_remote: false,
        baud: 1200,
        ..DmmConfig::default()
    });
    t.send_line("VOLT:NPLC 0.02;:ZERO:AUTO OFF;:SAMP:COUN 100")
        .await
        .unwrap();
    t.send_line("INIT;*OPC?").await.unwrap();
    t.read_line(T).await.unwrap();
    let t0 = Instant::now();
    t.send_line("FETC?").await.unwrap();
    let r = t.read_line(Some(Duration::from_secs(60))).await.unwrap();
    assert_eq!(r.len() + 2, 100 * 16 + 1);
    let s = t0.elapsed().as_secs_f64();
    let want = (6.0 + 1601.0) * 11.0 / 1200.0;
    assert!((s - want).abs() / want < 0.01, "{s} vs {want}");
}

#[tokio::test(start_paused = true)]
async fn dmm_time_scale_speeds_everything_up() {
    let (mut t, _h) = meter(DmmConfig {
        strict_remote: false,
        time_scale: 10.0,
        ..DmmConfig::default()
    });
    t.send_line("VOLT:NPLC 10;:SAMP:COUN 10").await.unwrap();
    let t0 = Instant::now();
    assert_eq!(q(&mut t, "READ?").await.split(',').count(), 10);
    let s = t0.elapsed().as_secs_f64();
    let want = (0.020 + 10.0 * 0.4015) / 10.0;
    assert!((s - want).abs() < 0.01, "{s} vs {want}");
}
