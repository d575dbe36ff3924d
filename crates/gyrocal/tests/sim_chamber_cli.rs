//! `gyrocal sim --chamber`: the simulated chamber served beside the meter and the table, on a
//! pseudo-terminal (Modbus RTU, the real Watlow F4 driver opening its path) and on Modbus TCP
//! (`--chamber-tcp`, the real driver connecting), and its state in the final JSON line. Real
//! time with a time scale (pseudo-terminals and virtual time do not mix).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::time::Duration;

use common::sim::Sim;
use gyrocal_chamber::{AlarmRegister, Chamber, SafeState, WatlowConfig, WatlowF4};

/// `gyrocal sim --time-scale 60 --seed 7 EXTRA` (the shared helper of `tests/common/sim.rs`).
fn sim(extra: &[&str]) -> Sim {
    let mut args: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![&"--time-scale", &"60", &"--seed", &"7"];
    for e in extra {
        args.push(e);
    }
    Sim::start(&args)
}

/// Sets 40 °C, waits 2 real seconds (2 sim minutes at × 60), reads: the air has ramped at
/// the chamber's 3 °C/min, not jumped; then the safe state.
async fn drive(f4: &mut WatlowF4) {
    let id = f4.connect().await.unwrap();
    assert!(id.model.contains("F4"), "{id:?}");
    f4.set_setpoint(40.0).await.unwrap();
    tokio::time::sleep(Duration::from_secs(2)).await;
    let r = f4.read().await.unwrap();
    assert_eq!(r.setpoint_c, 40.0);
    // 2 sim minutes (and the transactions' time) at 3 °C/min from 23: about 29 °C
    assert!(r.air_c > 27.0 && r.air_c < 32.0, "{r:?}");
    assert!(r.product_c.unwrap() < r.air_c, "the product lags: {r:?}");
    let report = f4.go_safe(SafeState::default()).await;
    assert!(report.confirmed, "{report:?}");
}

#[test]
fn chamber_on_a_pseudo_terminal_answers_the_watlow_driver() {
    let sim = sim(&["--chamber", "watlow_f4"]);
    assert_eq!(sim.info()["chamber_model"], "watlow_f4");
    let path = sim.chamber().to_string();
    assert!(path.starts_with("/dev/"), "{path}");
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut f4 = WatlowF4::open_rtu(&path, 9600, WatlowConfig::default()).unwrap();
        drive(&mut f4).await;
    });
    let last = sim.finish();
    assert_eq!(last["chamber"]["setpoint_c"], 23.0, "{last}");
    assert!(
        last["chamber"]["requests_seen"].as_u64().unwrap() >= 10,
        "{last}"
    );
}

/// The driver reading the simulated F4's door alarm (register 1061, 1 when latched).
fn door_alarm() -> WatlowConfig {
    WatlowConfig {
        alarms: vec![AlarmRegister {
            register: 1061,
            mask: 0xFFFF,
            active: 1,
            name: "door open".into(),
        }],
        ..WatlowConfig::default()
    }
}

#[test]
fn chamber_on_modbus_tcp_answers_the_watlow_driver() {
    // a door opened 5 sim minutes in (5 real seconds at × 60), read through the driver's
    // alarm registers (the simulated F4's 1061, 1 when latched)
    let sim = sim(&["--chamber-tcp", "0", "--fault", "chamber:door@t=300s"]);
    assert_eq!(sim.info()["faults"][0], "chamber:door@t=300s");
    let addr = sim.chamber().to_string();
    assert!(addr.starts_with("tcp://127.0.0.1:"), "{addr}");
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let mut f4 = WatlowF4::connect_tcp(&addr, door_alarm()).await.unwrap();
        drive(&mut f4).await;
        // (that no alarm is there before its time is asserted in virtual time, in the
        // simulator's own tests; real time here only makes sure it has come)
        tokio::time::sleep(Duration::from_secs(4)).await;
        assert_eq!(f4.read().await.unwrap().alarms, ["door open"]);
    });
    let last = sim.finish();
    assert_eq!(last["chamber"]["setpoint_c"], 23.0, "{last}");
    assert_eq!(last["chamber"]["alarms"][0], "door open", "{last}");
    assert_eq!(last["faults"][0]["fired"], true, "{last}");
}

/// The simulated chamber's panel (SIGUSR1 to `gyrocal sim`): a latched alarm stays latched
/// however often it is read, until the operator presses the reset; then the driver reads none.
#[test]
fn the_panels_reset_clears_a_latched_alarm() {
    let sim = sim(&["--chamber-tcp", "0", "--fault", "chamber:door@request1"]);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let mut f4 = rt.block_on(async {
        let mut f4 = WatlowF4::connect_tcp(sim.chamber(), door_alarm())
            .await
            .unwrap();
        f4.connect().await.unwrap();
        for _ in 0..2 {
            assert_eq!(f4.read().await.unwrap().alarms, ["door open"]);
        }
        f4
    });
    let said = sim.reset_chamber_alarms();
    assert_eq!(said["cleared"], serde_json::json!(["door open"]), "{said}");
    rt.block_on(async {
        assert!(f4.read().await.unwrap().alarms.is_empty());
    });
    // a second press clears nothing more, and says so
    assert_eq!(sim.reset_chamber_alarms()["cleared"], serde_json::json!([]));
    let last = sim.finish();
    assert_eq!(last["chamber"]["alarms"], serde_json::json!([]), "{last}");
}

#[test]
fn an_espec_over_tcp_is_refused_plainly() {
    let out = common::gyrocal()
        .args(["sim", "--chamber", "espec", "--chamber-tcp", "0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--chamber-tcp serves Modbus TCP"), "{err}");
}

#[test]
fn an_espec_on_a_pseudo_terminal_answers_the_espec_driver() {
    let sim = sim(&["--chamber", "espec"]);
    assert_eq!(sim.info()["chamber_model"], "espec");
    let path = sim.chamber().to_string();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let config = gyrocal_chamber::EspecConfig {
            mode_query: true,
            ..gyrocal_chamber::EspecConfig::default()
        };
        let mut espec = gyrocal_chamber::Espec::open(&path, config).await.unwrap();
        let id = espec.connect().await.unwrap();
        assert!(id.detail.contains("T,T,S2,160.0"), "{id:?}");
        espec.set_setpoint(10.0).await.unwrap();
        let r = espec.read().await.unwrap();
        assert_eq!(r.setpoint_c, 10.0);
        assert_eq!(r.mode, gyrocal_chamber::ChamberMode::Constant);
        let report = espec.go_safe(SafeState::Standby).await;
        assert!(report.confirmed, "{report:?}");
    });
    let last = sim.finish();
    assert_eq!(last["chamber"]["setpoint_c"], 10.0, "{last}");
}
