//! The simulated Watlow F4: its exact Modbus RTU frames and TCP ADUs, and the real
//! gyrocal-chamber driver against it in virtual time (ramps, lags, alarms, exceptions, CRC
//! errors, the safe states, a silent controller).

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_chamber::{
    AlarmRegister, Chamber, ChamberErrorKind, SafeState, WatlowConfig, WatlowF4,
};
use gyrocal_sim::bench::{Bench, BenchConfig};
use gyrocal_sim::chamber::{
    ChamberAlarm, ChamberFault, ChamberFaultKind, ChamberHandle, ChamberSimConfig, ChamberTrigger,
    ThermalConfig,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::time::Instant;

/// CRC-16/Modbus written again here (the Modbus over Serial Line specification's
/// algorithm), so the test does not trust the simulator's own.
fn crc(bytes: &[u8]) -> [u8; 2] {
    let mut c: u16 = 0xFFFF;
    for &b in bytes {
        c ^= u16::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                (c >> 1) ^ 0xA001
            } else {
                c >> 1
            };
        }
    }
    c.to_le_bytes()
}

fn framed(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc(body));
    f
}

fn quiet() -> ChamberSimConfig {
    ChamberSimConfig {
        thermal: ThermalConfig {
            sensor_noise_c: 0.0,
            ..ThermalConfig::default()
        },
        latency_s: 0.0,
        ..ChamberSimConfig::default()
    }
}

fn raw(config: ChamberSimConfig) -> (DuplexStream, ChamberHandle) {
    let (host, dev) = tokio::io::duplex(4096);
    let h = ChamberHandle::new(config, 1.0, 7);
    h.serve(dev);
    (host, h)
}

/// Sends `request`, returns what came back within 1 s (empty: silence).
async fn exchange(link: &mut DuplexStream, request: &[u8]) -> Vec<u8> {
    link.write_all(request).await.unwrap();
    let mut out = Vec::new();
    let mut buf = [0u8; 256];
    while let Ok(Ok(n)) =
        tokio::time::timeout(Duration::from_millis(200), link.read(&mut buf)).await
    {
        if n == 0 {
            break;
        }
        out.extend_from_slice(&buf[..n]);
    }
    out
}

#[tokio::test(start_paused = true)]
async fn rtu_frames_byte_for_byte() {
    let (mut l, h) = raw(quiet());
    // the driver's connect: units, input 1's decimals, range (README's session)
    assert_eq!(
        exchange(&mut l, &[0x01, 0x03, 0x03, 0x85, 0x00, 0x01, 0x95, 0xA7]).await,
        [0x01, 0x03, 0x02, 0x00, 0x01, 0x79, 0x84]
    );
    assert_eq!(
        exchange(&mut l, &[0x01, 0x03, 0x02, 0x5E, 0x00, 0x01, 0xE4, 0x60]).await,
        [0x01, 0x03, 0x02, 0x00, 0x01, 0x79, 0x84]
    );
    assert_eq!(
        exchange(&mut l, &[0x01, 0x03, 0x02, 0x5A, 0x00, 0x02, 0xE5, 0xA0]).await,
        [0x01, 0x03, 0x04, 0xFD, 0x44, 0x07, 0x08, 0x88, 0x7C]
    );
    // the air at rest: 23.0 °C = 230 = 00 E6 (no sensor noise here)
    assert_eq!(
        exchange(&mut l, &framed(&[0x01, 0x03, 0x00, 0x64, 0x00, 0x01])).await,
        framed(&[0x01, 0x03, 0x02, 0x00, 0xE6])
    );
    // write 300 = 25.0 °C: the echo; read back
    assert_eq!(
        exchange(&mut l, &[0x01, 0x06, 0x01, 0x2C, 0x00, 0xFA, 0xC9, 0xBC]).await,
        [0x01, 0x06, 0x01, 0x2C, 0x00, 0xFA, 0xC9, 0xBC]
    );
    assert_eq!(h.setpoint_c(), 25.0);
    assert_eq!(
        exchange(&mut l, &[0x01, 0x03, 0x01, 0x2C, 0x00, 0x01, 0x44, 0x3F]).await,
        [0x01, 0x03, 0x02, 0x00, 0xFA, 0x38, 0x07]
    );
    // a negative setpoint by write multiple: −20.5 °C = FF 33
    assert_eq!(
        exchange(
            &mut l,
            &framed(&[0x01, 0x10, 0x01, 0x2C, 0x00, 0x01, 0x02, 0xFF, 0x33])
        )
        .await,
        framed(&[0x01, 0x10, 0x01, 0x2C, 0x00, 0x01])
    );
    assert_eq!(h.setpoint_c(), -20.5);
    // exceptions: an unmapped register (the README's exception frame), a function the F4
    // does not take, a setpoint outside the range 602/603 (200.0 °C = 07 D0)
    assert_eq!(
        exchange(&mut l, &framed(&[0x01, 0x03, 0x03, 0x84, 0x00, 0x01])).await,
        [0x01, 0x83, 0x02, 0xC0, 0xF1]
    );
    assert_eq!(
        exchange(&mut l, &framed(&[0x01, 0x04, 0x00, 0x64, 0x00, 0x01])).await,
        framed(&[0x01, 0x84, 0x01])
    );
    assert_eq!(
        exchange(&mut l, &framed(&[0x01, 0x06, 0x01, 0x2C, 0x07, 0xD0])).await,
        framed(&[0x01, 0x86, 0x03])
    );
    assert_eq!(h.setpoint_c(), -20.5, "a refused setpoint is not taken");
    // silence: another slave, a bad CRC; then a good frame is answered again
    assert!(
        exchange(&mut l, &framed(&[0x02, 0x03, 0x03, 0x85, 0x00, 0x01]))
            .await
            .is_empty()
    );
    assert!(
        exchange(&mut l, &[0x01, 0x03, 0x03, 0x85, 0x00, 0x01, 0x95, 0xA8])
            .await
            .is_empty()
    );
    assert_eq!(
        exchange(&mut l, &[0x01, 0x03, 0x03, 0x85, 0x00, 0x01, 0x95, 0xA7]).await,
        [0x01, 0x03, 0x02, 0x00, 0x01, 0x79, 0x84]
    );
    // an alarm latched reads 1 until a write of 0 resets it
    h.latch_alarm(ChamberAlarm::Door);
    let read_1061 = framed(&[0x01, 0x03, 0x04, 0x25, 0x00, 0x01]);
    assert_eq!(
        exchange(&mut l, &read_1061).await,
        framed(&[0x01, 0x03, 0x02, 0x00, 0x01])
    );
    assert_eq!(
        exchange(&mut l, &framed(&[0x01, 0x06, 0x04, 0x25, 0x00, 0x00])).await,
        framed(&[0x01, 0x06, 0x04, 0x25, 0x00, 0x00])
    );
    assert_eq!(
        exchange(&mut l, &read_1061).await,
        framed(&[0x01, 0x03, 0x02, 0x00, 0x00])
    );
    assert!(h.alarms().is_empty());
}

#[tokio::test(start_paused = true)]
async fn tcp_adus_echo_the_transaction_id() {
    let (mut host, dev) = tokio::io::duplex(4096);
    let h = ChamberHandle::new(quiet(), 1.0, 7);
    h.serve_tcp(dev);
    assert_eq!(
        exchange(
            &mut host,
            &[
                0x00, 0x07, 0x00, 0x00, 0x00, 0x06, 0x01, 0x03, 0x03, 0x85, 0x00, 0x01
            ]
        )
        .await,
        [
            0x00, 0x07, 0x00, 0x00, 0x00, 0x05, 0x01, 0x03, 0x02, 0x00, 0x01
        ]
    );
    assert_eq!(
        exchange(
            &mut host,
            &[
                0x12, 0x34, 0x00, 0x00, 0x00, 0x06, 0x01, 0x06, 0x01, 0x2C, 0x02, 0x58
            ]
        )
        .await,
        [
            0x12, 0x34, 0x00, 0x00, 0x00, 0x06, 0x01, 0x06, 0x01, 0x2C, 0x02, 0x58
        ]
    );
    assert_eq!(h.setpoint_c(), 60.0);
    // an exception in an ADU
    assert_eq!(
        exchange(
            &mut host,
            &[
                0x00, 0x08, 0x00, 0x00, 0x00, 0x06, 0x01, 0x03, 0x03, 0x84, 0x00, 0x01
            ]
        )
        .await,
        [0x00, 0x08, 0x00, 0x00, 0x00, 0x03, 0x01, 0x83, 0x02]
    );
}

fn alarms() -> Vec<AlarmRegister> {
    vec![
        AlarmRegister {
            register: 1061,
            mask: 0xFFFF,
            active: 1,
            name: "door open".into(),
        },
        AlarmRegister {
            register: 1063,
            mask: 0xFFFF,
            active: 1,
            name: "over-temperature".into(),
        },
    ]
}

/// A bench with a Watlow F4 chamber, and the real driver on its link, connected.
async fn f4(chamber: ChamberSimConfig, driver: WatlowConfig) -> (WatlowF4, ChamberHandle) {
    let mut bench = Bench::spawn(BenchConfig {
        chamber: Some(chamber),
        ..BenchConfig::default()
    });
    let link = bench.chamber_link().unwrap();
    let handle = bench.handle.chamber.clone().unwrap();
    let mut f4 = WatlowF4::over_stream(link, "sim", 9600, driver).unwrap();
    f4.connect().await.unwrap();
    (f4, handle)
}

fn with_alarms() -> WatlowConfig {
    WatlowConfig {
        alarms: alarms(),
        ..WatlowConfig::default()
    }
}

async fn wait_min(min: f64) {
    tokio::time::sleep(Duration::from_secs_f64(min * 60.0)).await;
}

#[tokio::test(start_paused = true)]
async fn the_driver_sees_the_air_ramp_at_the_limited_rate_and_the_product_lag() {
    let (mut f4, h) = f4(ChamberSimConfig::default(), with_alarms()).await;
    let start = Instant::now();
    f4.set_setpoint(60.0).await.unwrap();
    assert_eq!(h.setpoint_c(), 60.0);
    // 3 °C/min up: 5 min after the write the air is 15 °C above the room's 23
    wait_min(5.0).await;
    let r = f4.read().await.unwrap();
    let truth = h.temperatures(Instant::now());
    let t_min = start.elapsed().as_secs_f64() / 60.0;
    assert!(
        (r.air_c - (23.0 + 3.0 * t_min)).abs() < 0.3,
        "{r:?} at {t_min} min"
    );
    assert_eq!(r.setpoint_c, 60.0);
    let product = r.product_c.unwrap();
    assert!((product - truth.case_c).abs() < 0.3, "{r:?} vs {truth:?}");
    assert!(product < r.air_c - 10.0, "the product lags the air: {r:?}");
    assert!(r.alarms.is_empty());
    // the ramp ends at 60 (37 °C at 3 °C/min: 12.3 min) and the air holds there
    wait_min(10.0).await;
    let r = f4.read().await.unwrap();
    assert!((r.air_c - 60.0).abs() < 0.3, "{r:?}");
    assert!(r.product_c.unwrap() < 55.0, "the product still lags: {r:?}");
    // three hours later the product (the gyro's case) has soaked, the inside with it
    wait_min(180.0).await;
    let r = f4.read().await.unwrap();
    assert!((r.product_c.unwrap() - 60.0).abs() < 0.3, "{r:?}");
    assert!((h.inside_c(Instant::now()) - 60.0).abs() < 0.05);
    // going down is slower (2 °C/min)
    f4.set_setpoint(40.0).await.unwrap();
    wait_min(5.0).await;
    let r = f4.read().await.unwrap();
    assert!((r.air_c - 50.0).abs() < 0.4, "{r:?}");
}

#[tokio::test(start_paused = true)]
async fn a_step_reaches_one_over_e_at_each_time_constant() {
    // air that steps at once, no sensor noise: the case is first order with case_tau_s
    let config = ChamberSimConfig {
        thermal: ThermalConfig {
            heat_c_per_min: 1e7,
            cool_c_per_min: 1e7,
            case_tau_s: 600.0,
            inside_tau_s: 1e-6,
            sensor_noise_c: 0.0,
            ..ThermalConfig::default()
        },
        decimals: 2,
        ..ChamberSimConfig::default()
    };
    let (mut f4, h) = f4(config, WatlowConfig::default()).await;
    f4.set_setpoint(83.0).await.unwrap();
    let set_at = Instant::now();
    tokio::time::sleep_until(set_at + Duration::from_secs(600)).await;
    let expected = 23.0 + 60.0 * (1.0 - (-1.0f64).exp());
    let product = f4.read().await.unwrap().product_c.unwrap();
    // the read itself takes a few tens of ms of virtual time: 0.1 °C/min of slope at most
    assert!((product - expected).abs() < 0.02, "{product} vs {expected}");
    // the inside, with its own time constant behind a case that steps at once
    let config = ChamberSimConfig {
        thermal: ThermalConfig {
            heat_c_per_min: 1e7,
            cool_c_per_min: 1e7,
            case_tau_s: 1e-6,
            inside_tau_s: 900.0,
            sensor_noise_c: 0.0,
            ..ThermalConfig::default()
        },
        ..ChamberSimConfig::default()
    };
    let h2 = ChamberHandle::new(config, 1.0, 1);
    h2.set_setpoint(-37.0);
    let t0 = h2.sim_time(Instant::now());
    let inside = h2.temperatures_at_sim(t0 + 900.0).inside_c;
    assert!(
        // within the 0.4 ms the "instant" air step takes at 1e7 °C/min
        (inside - (23.0 - 60.0 * (1.0 - (-1.0f64).exp()))).abs() < 1e-4,
        "{inside}"
    );
    drop(h);
}

#[tokio::test(start_paused = true)]
async fn alarms_latch_until_reset_and_a_timed_one_fires_on_time() {
    let config = ChamberSimConfig {
        faults: vec![ChamberFault {
            kind: ChamberFaultKind::Alarm(ChamberAlarm::OverTemperature),
            trigger: ChamberTrigger::Time(600.0),
            count: 1,
        }],
        ..ChamberSimConfig::default()
    };
    let (mut f4, h) = f4(config, with_alarms()).await;
    assert!(f4.read().await.unwrap().alarms.is_empty());
    h.latch_alarm(ChamberAlarm::Door);
    assert_eq!(f4.read().await.unwrap().alarms, ["door open"]);
    wait_min(5.0).await;
    assert_eq!(
        f4.read().await.unwrap().alarms,
        ["door open"],
        "latched, not a passing state"
    );
    h.reset_alarms();
    assert!(f4.read().await.unwrap().alarms.is_empty());
    tokio::time::sleep_until(Instant::now() + Duration::from_secs(300)).await;
    assert_eq!(f4.read().await.unwrap().alarms, ["over-temperature"]);
    let err = f4.reset_alarms().await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Unsupported);
}

#[tokio::test(start_paused = true)]
async fn exceptions_and_corrupted_replies_are_the_drivers_typed_errors() {
    let (mut f4, h) = f4(ChamberSimConfig::default(), WatlowConfig::default()).await;
    // an exception on the setpoint register
    h.exception_on_register(300, 2);
    let err = f4.set_setpoint(30.0).await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Instrument, "{err}");
    assert!(err.to_string().contains("exception 2"), "{err}");
    h.clear_register_exceptions();
    f4.set_setpoint(30.0).await.unwrap();
    // an exception fault on the next request: a read refused, not asked again
    let n = h.requests_seen();
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Exception,
        trigger: ChamberTrigger::Request(n + 1),
        count: 1,
    });
    let err = f4.read().await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Instrument, "{err}");
    assert!(err.to_string().contains("exception 4"), "{err}");
    assert!(f4.take_retries().is_empty());
    // one corrupted reply: asked again, the reading comes, the retry noted
    let n = h.requests_seen();
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Corrupt,
        trigger: ChamberTrigger::Request(n + 1),
        count: 1,
    });
    let r = f4.read().await.unwrap();
    assert!((r.air_c - 23.0).abs() < 0.3);
    let retries = f4.take_retries();
    assert_eq!(retries.len(), 1, "{retries:?}");
    // every reply corrupted: garbled after the retries
    let n = h.requests_seen();
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Corrupt,
        trigger: ChamberTrigger::Request(n + 1),
        count: 10,
    });
    let err = f4.read().await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Garbled, "{err}");
}

#[tokio::test(start_paused = true)]
async fn go_safe_is_confirmed_and_not_when_the_controller_is_silent() {
    let sim = ChamberSimConfig {
        chamber_on_output: Some(1),
        ..ChamberSimConfig::default()
    };
    let driver = WatlowConfig {
        chamber_on_output: Some(1),
        ..WatlowConfig::default()
    };
    let (mut f4, h) = f4(sim, driver).await;
    f4.set_setpoint(70.0).await.unwrap();
    wait_min(30.0).await;
    let report = f4.go_safe(SafeState::default()).await;
    assert!(report.confirmed, "{report:?}");
    assert_eq!(h.setpoint_c(), 23.0);
    // standby: the chamber-on output written 0 and read back; the air drifts to the room
    f4.set_setpoint(70.0).await.unwrap();
    wait_min(30.0).await;
    let report = f4.go_safe(SafeState::Standby).await;
    assert!(report.confirmed, "{report:?}");
    wait_min(60.0).await;
    assert!((h.temperatures(Instant::now()).air_c - 23.0).abs() < 1e-9);
    // silent: a read times out after exactly 3 × 1 s, go_safe says not confirmed
    h.set_silent(true);
    let t = Instant::now();
    let err = f4.read().await.unwrap_err();
    assert_eq!(err.kind(), ChamberErrorKind::Timeout, "{err}");
    let took = t.elapsed().as_secs_f64();
    assert!((3.0..3.05).contains(&took), "{took}");
    let report = f4.go_safe(SafeState::default()).await;
    assert!(!report.confirmed, "{report:?}");
}

#[tokio::test(start_paused = true)]
async fn a_profile_running_is_terminated_before_the_setpoint() {
    let sim = ChamberSimConfig {
        start_in_profile: true,
        ..ChamberSimConfig::default()
    };
    let (mut f4, h) = f4(sim, WatlowConfig::default()).await;
    assert_eq!(
        f4.read().await.unwrap().mode,
        gyrocal_chamber::ChamberMode::Profile
    );
    f4.set_setpoint(-10.0).await.unwrap();
    assert_eq!(h.mode(), gyrocal_sim::chamber::SimMode::Constant);
    assert_eq!(
        f4.read().await.unwrap().mode,
        gyrocal_chamber::ChamberMode::Constant
    );
}

#[tokio::test(start_paused = true)]
async fn the_driver_over_modbus_tcp_and_a_corrupted_adu() {
    let (host, dev) = tokio::io::duplex(4096);
    let h = ChamberHandle::new(ChamberSimConfig::default(), 1.0, 9);
    h.serve_tcp(dev);
    let mut f4 = WatlowF4::over_tcp_stream(host, "sim", with_alarms()).unwrap();
    f4.connect().await.unwrap();
    f4.set_setpoint(-30.0).await.unwrap();
    wait_min(10.0).await;
    let r = f4.read().await.unwrap();
    assert!((r.air_c - 3.0).abs() < 0.4, "2 °C/min down from 23: {r:?}");
    h.latch_alarm(ChamberAlarm::Door);
    assert_eq!(f4.read().await.unwrap().alarms, ["door open"]);
    // a corrupted ADU (protocol identifier 1) is garbled: asked again, noted
    let n = h.requests_seen();
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Corrupt,
        trigger: ChamberTrigger::Request(n + 1),
        count: 1,
    });
    f4.read().await.unwrap();
    assert_eq!(f4.take_retries().len(), 1);
}

#[tokio::test(start_paused = true)]
async fn slow_replies_are_late_then_too_late() {
    let (mut f4, h) = f4(ChamberSimConfig::default(), WatlowConfig::default()).await;
    // half a second late: within the driver's 1 s, each of the 3 transactions of a read
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Slow(0.5),
        trigger: ChamberTrigger::Request(h.requests_seen() + 1),
        count: 3,
    });
    let t = Instant::now();
    f4.read().await.unwrap();
    let took = t.elapsed().as_secs_f64();
    assert!((1.5..1.7).contains(&took), "{took}");
    assert!(f4.take_retries().is_empty());
    // two seconds late, every reply: the read fails. Late replies come while the driver
    // waits for a later request's, so it sees a timeout or (RTU has no transaction id: the
    // driver's README) a reply of the wrong length, garbled; never a reading
    h.arm(ChamberFault {
        kind: ChamberFaultKind::Slow(2.0),
        trigger: ChamberTrigger::Request(h.requests_seen() + 1),
        count: 0,
    });
    let err = f4.read().await.unwrap_err();
    assert!(
        matches!(
            err.kind(),
            ChamberErrorKind::Timeout | ChamberErrorKind::Garbled
        ),
        "{err}"
    );
    let report = f4.go_safe(SafeState::default()).await;
    assert!(!report.confirmed, "{report:?}");
}
