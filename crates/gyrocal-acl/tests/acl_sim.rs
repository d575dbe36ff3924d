//! The ACL driver against the simulated table, in virtual time over an in-memory pipe.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_sim::table::{SimMode, TableConfig, TableFaults, TableHandle};
use gyrocal_table::{RateTable, SettleCriteria, TableErrorKind, TableState};
use tokio::time::Instant;

mod common;
use common::{Table, enabled_sim_table, let_sim_run};

async fn bench(config: TableConfig) -> (Table, TableHandle) {
    let (table, handle) = enabled_sim_table(config, 7).await;
    assert_eq!(table.state(), TableState::Servoed);
    assert!(handle.interlock_closed());
    (table, handle)
}

#[tokio::test(start_paused = true)]
async fn table_sim_ramps_both_ways_settles_and_records() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    let criteria = SettleCriteria::default();

    let t0 = Instant::now();
    table.set_rate(20.0, 5.0).await.unwrap();
    let report = table.wait_at_rate(&criteria).await.unwrap();
    assert_eq!(report.ramp_time, Duration::from_secs(4));
    assert!(report.settled_after >= Duration::from_secs(6), "{report:?}");
    assert!(
        t0.elapsed() < Duration::from_secs(7),
        "settles promptly: {:?}",
        t0.elapsed()
    );
    assert!((report.window.mean - 20.0).abs() < 1e-3, "{report:?}");
    assert!(report.window.count >= 20);
    assert_eq!(table.state(), TableState::AtRate { rate: 20.0 });
    assert!((sim.actual_rate(Instant::now()) - 20.0).abs() < 1e-3);
    assert_eq!(sim.demanded_rate(), 20.0);

    // what the table did while the (here: pretend) multimeter acquired for 10 s
    let (out, stats) = table
        .record_while(Duration::from_millis(100), async {
            tokio::time::sleep(Duration::from_secs(10)).await;
            42
        })
        .await
        .unwrap();
    assert_eq!(out, 42);
    assert!((99..=102).contains(&stats.count), "{stats:?}");
    assert!((stats.mean - 20.0).abs() < 2e-4, "{stats:?}");
    assert!(stats.std > 0.0 && stats.std < 2e-3, "{stats:?}");
    assert!(stats.min < stats.mean && stats.mean < stats.max);

    // reverse through zero: 35 deg/s at 5 deg/s^2 is at least 7 s
    table.set_rate(-15.0, 5.0).await.unwrap();
    let report = table.wait_at_rate(&criteria).await.unwrap();
    assert_eq!(report.ramp_time, Duration::from_secs(7));
    assert!((report.window.mean + 15.0).abs() < 1e-3);
    let p = table.read_position().await.unwrap();
    assert!((0.0..360.0).contains(&p));
    assert!((sim.position(Instant::now()) - p).abs() < 1e-3);

    table.stop().await.unwrap();
    assert_eq!(table.state(), TableState::Stopping);
    table.wait_stopped(Duration::from_secs(10)).await.unwrap();
    assert_eq!(table.state(), TableState::Servoed);
    assert!(sim.is_stopped());
    assert_eq!(sim.mode(), SimMode::Off);
}

#[tokio::test(start_paused = true)]
async fn table_sim_never_settling_table_times_out_as_a_fault_and_is_stopped() {
    let config = TableConfig {
        never_settle: true,
        ..TableConfig::default()
    };
    let (mut table, sim) = bench(config).await;
    table.set_rate(10.0, 5.0).await.unwrap();
    let criteria = SettleCriteria {
        timeout: Duration::from_secs(20),
        ..Default::default()
    };
    let t0 = Instant::now();
    let err = table.wait_at_rate(&criteria).await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault, "{err}");
    assert!(err.to_string().contains("not settled"), "{err}");
    let waited = t0.elapsed();
    assert!(
        waited >= Duration::from_secs(22) && waited < Duration::from_secs(23),
        "{waited:?}"
    );
    assert_eq!(table.state(), TableState::Faulted);
    // the driver stopped the table on the way out
    let_sim_run().await;
    assert_eq!(sim.mode(), SimMode::Off);
    assert_eq!(sim.demanded_rate(), 0.0);
    // a faulted driver refuses demands until enabled again
    assert_eq!(
        table.set_rate(1.0, 1.0).await.unwrap_err().kind(),
        TableErrorKind::State
    );
}

#[tokio::test(start_paused = true)]
async fn table_sim_limits_are_refused_before_sending() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    let err = table.set_rate(45.0, 5.0).await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Limit);
    let err = table.set_rate(10.0, 0.0).await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Limit);
    assert_eq!(sim.demanded_rate(), 0.0);
    assert_eq!(table.state(), TableState::Servoed);
    // nothing reached the table's error queue either
    table.heartbeat().await.unwrap();
}

#[tokio::test(start_paused = true)]
async fn table_sim_fault_latched_mid_ramp_stops_the_run_with_the_tables_message() {
    let config = TableConfig {
        faults: TableFaults {
            inject_at_rate: Some(8.0),
            message: "Feedback loss on axis 1".into(),
            ..Default::default()
        },
        ..TableConfig::default()
    };
    let (mut table, sim) = bench(config).await;
    let t0 = Instant::now();
    table.set_rate(20.0, 4.0).await.unwrap();
    table.start_recording();
    let err = table
        .wait_at_rate(&SettleCriteria::default())
        .await
        .unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault, "{err}");
    assert!(
        err.to_string().contains("220,\"Feedback loss on axis 1\""),
        "{err}"
    );
    // latched at 8 deg/s, i.e. 2 s into the ramp, seen by the next 100 ms sample
    let seen = t0.elapsed();
    assert!(
        seen >= Duration::from_secs(2) && seen <= Duration::from_millis(2200),
        "{seen:?}"
    );
    let stats = table.stop_recording();
    assert!(stats.max <= 8.01, "{stats:?}");
    assert_eq!(table.state(), TableState::Faulted);
    assert!(sim.fault().is_some());
    assert!(!sim.interlock_closed());

    // recovery: wait for the abort profile, then an explicit enable resets the latch
    table.wait_stopped(Duration::from_secs(5)).await.unwrap();
    assert_eq!(
        table.state(),
        TableState::Faulted,
        "stopping does not clear a fault"
    );
    table.enable().await.unwrap();
    assert_eq!(table.state(), TableState::Servoed);
    assert_eq!(sim.fault(), None);
}

#[tokio::test(start_paused = true)]
async fn table_sim_runtime_rate_trip_is_a_fault() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    table.set_rate(5.0, 5.0).await.unwrap();
    table
        .wait_at_rate(&SettleCriteria::default())
        .await
        .unwrap();
    sim.trip();
    let err = table.sample().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault);
    assert!(err.to_string().contains("Rate trip"), "{err}");
    assert_eq!(sim.mode(), SimMode::Abort);
}

#[tokio::test(start_paused = true)]
async fn table_sim_emergency_stop_opens_the_interlock() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    table.set_rate(10.0, 5.0).await.unwrap();
    table
        .wait_at_rate(&SettleCriteria::default())
        .await
        .unwrap();
    let handle = table.stop_handle();
    handle.emergency_stop().await.unwrap();
    let_sim_run().await;
    assert_eq!(sim.mode(), SimMode::Abort);
    assert!(!sim.interlock_closed());
    assert_eq!(table.state(), TableState::Stopping);
    // the interlock event is expected after our own emergency stop: not a fault
    table.wait_stopped(Duration::from_secs(5)).await.unwrap();
    table.heartbeat().await.unwrap();
    assert_eq!(table.state(), TableState::Connected);
    assert_eq!(sim.mode(), SimMode::Off);
    assert!(sim.is_stopped());
    // demands need the servo again
    assert_eq!(
        table.set_rate(1.0, 1.0).await.unwrap_err().kind(),
        TableErrorKind::State
    );
    table.enable().await.unwrap();
    table.set_rate(1.0, 1.0).await.unwrap();
    let_sim_run().await;
    assert_eq!(sim.demanded_rate(), 1.0);
}

#[tokio::test(start_paused = true)]
async fn table_sim_silent_table_fails_the_heartbeat() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    table.set_rate(10.0, 5.0).await.unwrap();
    sim.set_silent(true);
    let t0 = Instant::now();
    let err = table.heartbeat().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Timeout, "{err}");
    assert_eq!(
        t0.elapsed(),
        Duration::from_secs(2),
        "the heartbeat deadline"
    );
    assert_eq!(table.state(), TableState::Faulted);
    // the silent table ignored the stop the driver tried: that is why the run must end
    let_sim_run().await;
    assert_eq!(sim.demanded_rate(), 10.0);
    // silence during an acquisition ends it too
    let err = table
        .record_while(
            Duration::from_millis(100),
            tokio::time::sleep(Duration::from_secs(60)),
        )
        .await
        .unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Timeout);
    sim.set_silent(false);
    table.stop().await.unwrap();
    let_sim_run().await;
    assert_eq!(sim.demanded_rate(), 0.0);
}

#[tokio::test(start_paused = true)]
async fn table_sim_stop_guard_stops_a_table_left_turning() {
    let (mut table, sim) = bench(TableConfig::default()).await;
    table.set_rate(10.0, 5.0).await.unwrap();
    {
        let _guard = table.stop_handle().guard();
        // an early return or panic here drops the guard
    }
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(sim.mode(), SimMode::Off);
    assert_eq!(sim.demanded_rate(), 0.0);
    tokio::time::sleep(Duration::from_secs(5)).await;
    assert!(sim.is_stopped());
}
