//! The simulated Espec SH-641: its exact lines, and the real gyrocal-chamber driver against
//! it in virtual time.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_chamber::{Chamber, ChamberErrorKind, Espec, EspecConfig, SafeState};
use gyrocal_link::{StreamTransport, Transport, memory_pair};
use gyrocal_sim::bench::{Bench, BenchConfig};
use gyrocal_sim::chamber::{
    ChamberAlarm, ChamberFault, ChamberFaultKind, ChamberHandle, ChamberModel, ChamberSimConfig,
    ChamberTrigger, ThermalConfig,
};
use tokio::io::DuplexStream;
use tokio::time::Instant;

fn espec() -> ChamberSimConfig {
    ChamberSimConfig {
        model: ChamberModel::Espec,
        ..ChamberSimConfig::default()
    }
}

async fn q(link: &mut StreamTransport<DuplexStream>, line: &str) -> String {
    link.write_raw(format!("{line}\r\n").as_bytes())
        .await
        .unwrap();
    link.read_line(Some(Duration::from_secs(1))).await.unwrap()
}

#[tokio::test(start_paused = true)]
async fn espec_lines_exactly() {
    let (mut l, dev) = memory_pair("sim-espec");
    let h = ChamberHandle::new(
        ChamberSimConfig {
            thermal: ThermalConfig {
                sensor_noise_c: 0.0,
                ..ThermalConfig::default()
            },
            ..espec()
        },
        1.0,
        3,
    );
    h.serve(dev);
    assert_eq!(q(&mut l, "TYPE?").await, "T,T,S2,160.0");
    assert_eq!(q(&mut l, "TEMP?").await, "23.0,23.0,180.0,-70.0");
    assert_eq!(q(&mut l, "TEMP,S25.0").await, "OK:TEMP,S25.0");
    assert_eq!(q(&mut l, "TEMP,S200.0").await, "NA:DATA OUT OF RANGE");
    assert_eq!(q(&mut l, "TEMP,Sabc").await, "NA:DATA NOT READY");
    assert_eq!(q(&mut l, "MODE?").await, "CONSTANT");
    assert_eq!(q(&mut l, "MODE,STANDBY").await, "OK:MODE,STANDBY");
    assert_eq!(q(&mut l, "MODE?").await, "STANDBY");
    assert_eq!(q(&mut l, "POWER,BOGUS").await, "NA:COMMAND ERR");
    assert_eq!(q(&mut l, "ALARM?").await, "0");
    h.latch_alarm(ChamberAlarm::Door);
    h.latch_alarm(ChamberAlarm::OverTemperature);
    assert_eq!(q(&mut l, "ALARM?").await, "2,1,5");
    assert_eq!(q(&mut l, "ALARM,RESET").await, "OK:ALARM,RESET");
    assert_eq!(q(&mut l, "ALARM?").await, "0");
    // in standby the air drifts to the room, whatever the setpoint (25 °C here)
    tokio::time::sleep(Duration::from_secs(600)).await;
    assert_eq!(q(&mut l, "TEMP?").await, "23.0,25.0,180.0,-70.0");
    // corrupted: a digit becomes #
    let n = h.requests_seen();
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Corrupt,
        trigger: ChamberTrigger::Request(n + 1),
        count: 1,
    });
    assert_eq!(q(&mut l, "TEMP?").await, "#3.0,25.0,180.0,-70.0");
}

async fn driver(
    config: ChamberSimConfig,
    driver: EspecConfig,
) -> (Espec<StreamTransport<DuplexStream>>, ChamberHandle) {
    let mut bench = Bench::spawn(BenchConfig {
        chamber: Some(config),
        ..BenchConfig::default()
    });
    let link = bench.chamber_transport().unwrap();
    let handle = bench.handle.chamber.clone().unwrap();
    let mut espec = Espec::over_transport(link, driver).unwrap();
    espec.connect().await.unwrap();
    (espec, handle)
}

#[tokio::test(start_paused = true)]
async fn the_espec_driver_sets_reads_and_goes_safe() {
    let (mut e, h) = driver(
        espec(),
        EspecConfig {
            mode_query: true,
            alarm_query: true,
            ..EspecConfig::default()
        },
    )
    .await;
    let start = Instant::now();
    e.set_setpoint(-20.0).await.unwrap();
    assert_eq!(h.setpoint_c(), -20.0);
    tokio::time::sleep(Duration::from_secs(600)).await;
    let r = e.read().await.unwrap();
    // 2 °C/min down from 23
    let t_min = start.elapsed().as_secs_f64() / 60.0;
    assert!(
        (r.air_c - (23.0 - 2.0 * t_min)).abs() < 0.3,
        "{r:?} at {t_min}"
    );
    assert_eq!(r.setpoint_c, -20.0);
    assert_eq!(r.product_c, None, "no product input on the Espec");
    assert!(r.alarms.is_empty());
    h.latch_alarm(ChamberAlarm::Door);
    assert_eq!(e.read().await.unwrap().alarms, ["alarm code 5"]);
    h.reset_alarms();
    let report = e.go_safe(SafeState::default()).await;
    assert!(report.confirmed, "{report:?}");
    assert_eq!(h.setpoint_c(), 23.0);
    let report = e.go_safe(SafeState::Standby).await;
    assert!(report.confirmed, "{report:?}");
    assert_eq!(h.mode(), gyrocal_sim::chamber::SimMode::Standby);
}

#[tokio::test(start_paused = true)]
async fn espec_refusals_and_silence_are_typed_errors() {
    let (mut e, h) = driver(espec(), EspecConfig::default()).await;
    let n = h.requests_seen();
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Exception,
        trigger: ChamberTrigger::Request(n + 1),
        count: 1,
    });
    let err = e.set_setpoint(30.0).await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Instrument, "{err}");
    assert!(err.to_string().contains("DEVICE FAULT"), "{err}");
    h.set_silent(true);
    let t = Instant::now();
    let err = e.read().await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Timeout, "{err}");
    let took = t.elapsed().as_secs_f64();
    assert!((30.0..30.1).contains(&took), "3 × 10 s: {took}");
    let report = e.go_safe(SafeState::default()).await;
    assert!(!report.confirmed, "{report:?}");
}
