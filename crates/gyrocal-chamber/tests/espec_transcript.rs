//! Transcript tests of the Espec text dialect: the exact lines (CR LF both ways) on an
//! in-memory link, checked by a scripted peer of this file's own, in virtual time.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use gyrocal_chamber::{Chamber, ChamberErrorKind, ChamberMode, Espec, EspecConfig, SafeState};
use gyrocal_link::{StreamTransport, memory_pair};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::task::JoinHandle;
use tokio::time::Instant;

type Driver = Espec<StreamTransport<DuplexStream>>;

/// A line the driver must send, and the controller's reply (none: silence).
fn ask(line: &str, reply: &str) -> (String, Option<String>) {
    (format!("{line}\r\n"), Some(format!("{reply}\r\n")))
}

fn silent(line: &str) -> (String, Option<String>) {
    (format!("{line}\r\n"), None)
}

fn peer(mut io: DuplexStream, script: Vec<(String, Option<String>)>) -> JoinHandle<()> {
    tokio::spawn(async move {
        for (i, (line, reply)) in script.into_iter().enumerate() {
            let mut got = vec![0u8; line.len()];
            io.read_exact(&mut got)
                .await
                .unwrap_or_else(|e| panic!("exchange {i}: {line:?} not received: {e}"));
            assert_eq!(String::from_utf8_lossy(&got), line, "exchange {i}");
            if let Some(reply) = reply {
                io.write_all(reply.as_bytes()).await.unwrap();
            }
        }
        let mut rest = Vec::new();
        io.read_to_end(&mut rest).await.unwrap();
        assert!(
            rest.is_empty(),
            "sent after the script: {:?}",
            String::from_utf8_lossy(&rest)
        );
    })
}

fn espec(config: EspecConfig, script: Vec<(String, Option<String>)>) -> (Driver, JoinHandle<()>) {
    let (host, device) = memory_pair("pipe");
    (
        Espec::over_transport(host, config).unwrap(),
        peer(device, script),
    )
}

fn connect_script() -> Vec<(String, Option<String>)> {
    vec![
        ask("TYPE?", "T,T,S2,160.0"),
        ask("TEMP?", "23.4,25.0,100.0,-40.0"),
    ]
}

fn with(
    mut a: Vec<(String, Option<String>)>,
    b: Vec<(String, Option<String>)>,
) -> Vec<(String, Option<String>)> {
    a.extend(b);
    a
}

async fn finish(e: Driver, peer: JoinHandle<()>) {
    drop(e);
    peer.await.unwrap();
}

#[tokio::test(start_paused = true)]
async fn connect_reads_the_identity_and_the_alarm_temperatures() {
    let (mut e, peer) = espec(EspecConfig::default(), connect_script());
    let id = e.connect().await.unwrap();
    assert!(id.detail.contains("TYPE? T,T,S2,160.0"), "{}", id.detail);
    // −40 .. 85 configured, −40 .. 100 the controller's alarms: the narrower.
    assert_eq!(e.limits(), (-40.0, 85.0));
    assert_eq!(e.describe(), "pipe (Espec, text)");
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn the_alarm_temperatures_narrow_the_limits_and_nothing_is_sent_beyond() {
    let (mut e, peer) = espec(
        EspecConfig::default(),
        vec![
            ask("TYPE?", "T,T,S2,160.0"),
            ask("TEMP?", "23.4,25.0,60.0,-10.0"),
        ],
    );
    e.connect().await.unwrap();
    assert_eq!(e.limits(), (-10.0, 60.0));
    let err = e.set_setpoint(70.0).await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Limit);
    assert!(err.to_string().contains("-10 .. 60"), "{err}");
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_setpoint_is_set_put_in_constant_mode_once_and_read_back() {
    let set = vec![
        ask("TEMP,S25.0", "OK:TEMP,S25.0"),
        ask("MODE,CONSTANT", "OK:MODE,CONSTANT"),
        ask("TEMP?", "23.4,25.0,100.0,-40.0"),
        ask("TEMP,S-20.5", "OK:TEMP,S-20.5"),
        ask("TEMP?", "22.9,-20.5,100.0,-40.0"),
    ];
    let (mut e, peer) = espec(EspecConfig::default(), with(connect_script(), set));
    e.connect().await.unwrap();
    e.set_setpoint(25.0).await.unwrap();
    e.set_setpoint(-20.5).await.unwrap();
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn na_is_an_instrument_error_with_the_controllers_reason() {
    let (mut e, peer) = espec(
        EspecConfig::default(),
        with(
            connect_script(),
            vec![ask("TEMP,S25.0", "NA:CONT NOT READY-1")],
        ),
    );
    e.connect().await.unwrap();
    let err = e.set_setpoint(25.0).await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Instrument);
    assert!(err.to_string().contains("CONT NOT READY-1"), "{err}");
    assert!(err.to_string().contains("TEMP,S25.0"), "{err}");
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_reading_has_the_air_and_setpoint_and_no_product() {
    let (mut e, peer) = espec(
        EspecConfig::default(),
        vec![ask("TEMP?", "-19.8,-20.0,100.0,-40.0")],
    );
    let r = e.read().await.unwrap();
    assert_eq!(r.air_c, -19.8);
    assert_eq!(r.setpoint_c, -20.0);
    assert_eq!(r.product_c, None);
    assert_eq!(r.mode, ChamberMode::Constant);
    assert!(r.alarms.is_empty());
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_garbled_reply_is_asked_again_and_noted() {
    let (mut e, peer) = espec(
        EspecConfig::default(),
        vec![
            ask("TEMP?", "23.4,25.0"),
            ask("TEMP?", "23.4,25.0,100.0,-40.0"),
        ],
    );
    let r = e.read().await.unwrap();
    assert_eq!(r.air_c, 23.4);
    let notes = e.take_retries();
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(notes[0].contains("2 fields instead of 4"), "{}", notes[0]);
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_silent_controller_times_out_exactly_after_its_retries() {
    let (mut e, peer) = espec(
        EspecConfig::default(),
        vec![silent("TEMP?"), silent("TEMP?"), silent("TEMP?")],
    );
    let t0 = Instant::now();
    let err = e.read().await.unwrap_err();
    assert_eq!(t0.elapsed(), Duration::from_secs(30));
    assert_eq!(err.kind(), ChamberErrorKind::Timeout);
    assert!(err.to_string().contains("the chamber is silent"), "{err}");
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn mode_and_alarms_when_their_queries_are_on() {
    let config = EspecConfig {
        mode_query: true,
        alarm_query: true,
        ..EspecConfig::default()
    };
    let (mut e, peer) = espec(
        config,
        vec![
            ask("TEMP?", "23.4,25.0,100.0,-40.0"),
            ask("MODE?", "STANDBY"),
            ask("ALARM?", "1,3"),
        ],
    );
    let r = e.read().await.unwrap();
    assert_eq!(r.mode, ChamberMode::Standby);
    assert_eq!(r.alarms, vec!["alarm code 3".to_string()]);
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn off_is_confirmed_by_the_acknowledgement_or_read_back() {
    let (mut e, peer) = espec(EspecConfig::default(), vec![ask("MODE,OFF", "OK:MODE,OFF")]);
    let report = e.go_safe(SafeState::Off).await;
    assert!(report.confirmed, "{}", report.detail);
    assert!(report.detail.contains("not read back"), "{}", report.detail);
    finish(e, peer).await;

    let config = EspecConfig {
        mode_query: true,
        ..EspecConfig::default()
    };
    let (mut e, peer) = espec(
        config,
        vec![
            ask("MODE,STANDBY", "OK:MODE,STANDBY"),
            ask("MODE?", "CONSTANT"),
        ],
    );
    let report = e.go_safe(SafeState::Standby).await;
    assert!(!report.confirmed, "acknowledged but read back otherwise");
    assert!(
        report.detail.contains("MODE? reads constant"),
        "{}",
        report.detail
    );
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn ambient_is_set_in_constant_mode_and_read_back() {
    let (mut e, peer) = espec(
        EspecConfig::default(),
        vec![
            ask("TEMP,S23.0", "OK:TEMP,S23.0"),
            ask("MODE,CONSTANT", "OK:MODE,CONSTANT"),
            ask("TEMP?", "-5.2,23.0,100.0,-40.0"),
        ],
    );
    let report = e.go_safe(SafeState::default()).await;
    assert!(report.confirmed, "{}", report.detail);
    assert!(
        report.detail.contains("setpoint 23.0 °C read back"),
        "{}",
        report.detail
    );
    finish(e, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_silent_controller_at_the_end_is_not_confirmed_and_the_command_not_repeated() {
    let (mut e, peer) = espec(EspecConfig::default(), vec![silent("TEMP,S23.0")]);
    let t0 = Instant::now();
    let report = e.go_safe(SafeState::default()).await;
    assert_eq!(t0.elapsed(), Duration::from_secs(10));
    assert!(!report.confirmed);
    assert!(
        report.detail.contains("not sent again"),
        "{}",
        report.detail
    );
    finish(e, peer).await;
}
