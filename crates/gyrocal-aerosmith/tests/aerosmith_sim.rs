//! The generic table over the experimental Aerosmith dialect against the simulated table
//! serving that dialect, in virtual time over an in-memory pipe.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_sim::table::{TableConfig, TableHandle};
use gyrocal_table::{RateTable, SettleCriteria, TableErrorKind, TableMode, TableState};
use tokio::time::Instant;

mod common;
use common::{Table, sim_aerosmith};

async fn bench(config: TableConfig) -> (Table, TableHandle) {
    let (mut table, handle) = sim_aerosmith(config, 7);
    table.connect().await.unwrap();
    assert_eq!(table.state(), TableState::Connected);
    table.enable().await.unwrap();
    assert_eq!(table.state(), TableState::Servoed);
    assert!(handle.interlock_closed());
    (table, handle)
}

#[tokio::test(start_paused = true)]
async fn aerosmith_sim_connect_enable_rate_record_stop_rest() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    let t0 = Instant::now();
    table.set_rate(20.0, 5.0).await.unwrap();
    let report = table
        .wait_at_rate(&SettleCriteria::default())
        .await
        .unwrap();
    assert_eq!(report.ramp_time, Duration::from_secs(4));
    assert!(t0.elapsed() >= Duration::from_secs(6), "{:?}", t0.elapsed());
    assert!((report.window.mean - 20.0).abs() < 1e-3, "{report:?}");
    assert_eq!(table.state(), TableState::AtRate { rate: 20.0 });

    let (out, stats) = table
        .record_while(Duration::from_millis(100), async {
            tokio::time::sleep(Duration::from_secs(5)).await;
            42
        })
        .await
        .unwrap();
    assert_eq!(out, 42);
    assert!(stats.count >= 50, "{stats:?}");
    assert!((stats.mean - 20.0).abs() < 1e-3, "{stats:?}");
    let position = table.read_position().await.unwrap();
    assert!((0.0..360.0).contains(&position));

    table.stop().await.unwrap();
    assert_eq!(table.state(), TableState::Stopping);
    let deadline = table.stop_deadline(20.0);
    let rest = table.wait_stopped(deadline).await.unwrap();
    assert_eq!(rest.mode, TableMode::Off);
    assert!(rest.rate_dps.abs() <= 0.01, "{rest:?}");
    // 20 deg/s at 5 deg/s^2: four seconds of deceleration, not declared rest before
    assert!(rest.waited >= Duration::from_secs(4), "{rest:?}");
    assert!(sim.is_stopped());
    assert_eq!(table.state(), TableState::Servoed);
    assert!(table.take_retries().is_empty());
}

#[tokio::test(start_paused = true)]
async fn aerosmith_sim_fault_mid_acquisition_faults_and_stops() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    table.set_rate(10.0, 5.0).await.unwrap();
    table
        .wait_at_rate(&SettleCriteria::default())
        .await
        .unwrap();
    let injector = sim.clone();
    let err = table
        .record_while(Duration::from_millis(100), async move {
            tokio::time::sleep(Duration::from_secs(1)).await;
            injector.inject_fault("Tracking error limit exceeded");
            tokio::time::sleep(Duration::from_secs(10)).await;
        })
        .await
        .unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault, "{err}");
    assert!(err.to_string().contains("fault bit"), "{err}");
    assert_eq!(table.state(), TableState::Faulted);
    // the abort profile runs out; SRV clears the fault and the table can turn again
    tokio::time::sleep(Duration::from_secs(2)).await;
    table.enable().await.unwrap();
    assert!(sim.fault().is_none());
    table.set_rate(-5.0, 5.0).await.unwrap();
    table
        .wait_at_rate(&SettleCriteria::default())
        .await
        .unwrap();
    table.stop().await.unwrap();
    table.wait_stopped(table.stop_deadline(5.0)).await.unwrap();
    assert!(sim.is_stopped());
}

#[tokio::test(start_paused = true)]
async fn aerosmith_sim_silent_table_is_a_fault_within_the_heartbeat_deadline() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    table.set_rate(5.0, 5.0).await.unwrap();
    sim.set_silent(true);
    let t0 = Instant::now();
    let err = table.sample().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Timeout, "{err}");
    assert!(t0.elapsed() <= Duration::from_secs(2) + Duration::from_millis(10));
    assert_eq!(table.state(), TableState::Faulted);
    assert_eq!(table.take_retries().len(), 3);
}
