//! The ACL driver against the simulated table's link faults (lost, garbled and noise-prefixed
//! replies, silence, an interlock that opens) and its rest check, in virtual time over an
//! in-memory pipe.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_sim::table::{DemandFault, ReplyFault, SimMode, TableConfig, TableHandle};
use gyrocal_table::{RateTable, SettleCriteria, TableErrorKind, TableMode, TableState};
use tokio::time::Instant;

mod common;
use common::{Table, enabled_sim_table, let_sim_run};

/// A connected, enabled table turning steadily at `rate` deg/s.
async fn turning(rate: f64) -> (Table, TableHandle) {
    let (mut table, sim) = enabled_sim_table(TableConfig::default(), 11).await;
    if rate != 0.0 {
        table.set_rate(rate, 5.0).await.unwrap();
        table
            .wait_at_rate(&SettleCriteria::default())
            .await
            .unwrap();
    }
    assert!(table.take_retries().is_empty());
    (table, sim)
}

#[tokio::test(start_paused = true)]
async fn lost_rate_reply_is_asked_again_and_the_sample_succeeds() {
    let (mut table, sim) = turning(10.0).await;
    sim.inject_reply_faults(ReplyFault::Drop, 1);
    let t0 = Instant::now();
    let rate = table.sample().await.unwrap();
    assert!((rate - 10.0).abs() < 0.01, "{rate}");
    // the first attempt had a third of the 2 s heartbeat deadline
    let waited = t0.elapsed();
    assert!(
        waited >= Duration::from_millis(666) && waited < Duration::from_millis(700),
        "{waited:?}"
    );
    assert_eq!(table.state(), TableState::AtRate { rate: 10.0 });
    assert_eq!(
        table.take_retries(),
        ["`:Read:Rate? 1`: no reply within 0.667 s; asked again (retry 1 of 2)"]
    );
    assert_eq!(sim.pending_reply_faults(), 0);
}

#[tokio::test(start_paused = true)]
async fn garbled_status_byte_is_asked_again() {
    let (mut table, sim) = turning(10.0).await;
    // the sample's `:Read:Rate?` goes through, its `*STB?` is garbled
    table.sample().await.unwrap();
    sim.inject_reply_faults(ReplyFault::Garble, 1);
    table.heartbeat().await.unwrap();
    let notes = table.take_retries();
    assert_eq!(notes.len(), 1, "{notes:#?}");
    assert!(
        notes[0].starts_with("`*STB?`: unusable reply \"#\""),
        "{notes:#?}"
    );
    assert!(
        notes[0].ends_with("asked again (retry 1 of 2)"),
        "{notes:#?}"
    );
    assert_eq!(table.state(), TableState::AtRate { rate: 10.0 });
}

#[tokio::test(start_paused = true)]
async fn noise_byte_before_a_reply_is_asked_again() {
    let (mut table, sim) = turning(-5.0).await;
    sim.inject_reply_faults(ReplyFault::Noise, 1);
    let t0 = Instant::now();
    let status = table.status().await.unwrap();
    assert_eq!(status.mode, TableMode::Rate);
    assert!(
        t0.elapsed() < Duration::from_millis(10),
        "garbled at once, no timeout"
    );
    let notes = table.take_retries();
    assert_eq!(notes.len(), 1, "{notes:#?}");
    assert!(
        notes[0].starts_with("`:Mode? 1`: garbled reply"),
        "{notes:#?}"
    );
    assert!(notes[0].contains("\\xff"), "{notes:#?}");
}

#[tokio::test(start_paused = true)]
async fn lost_error_check_after_a_demand_never_resends_the_demand() {
    let (mut table, sim) = turning(0.0).await;
    sim.arm_at_demand(1, DemandFault::Reply(ReplyFault::Drop, 1));
    table.set_rate(10.0, 5.0).await.unwrap();
    assert_eq!(sim.demands_seen(), 1, "the demand was sent once");
    let notes = table.take_retries();
    assert_eq!(notes.len(), 1, "{notes:#?}");
    assert!(
        notes[0].starts_with("`:System:Error?`: no reply"),
        "{notes:#?}"
    );
    assert!(
        notes[0].contains("a table error may be missing"),
        "{notes:#?}"
    );
    table
        .wait_at_rate(&SettleCriteria::default())
        .await
        .unwrap();
    assert_eq!(sim.demands_seen(), 1);
}

#[tokio::test(start_paused = true)]
async fn silent_table_still_fails_a_sample_within_the_heartbeat_deadline() {
    let (mut table, sim) = turning(10.0).await;
    sim.set_silent(true);
    let t0 = Instant::now();
    let err = table.sample().await.unwrap_err();
    let elapsed = t0.elapsed();
    let deadline = table.config().heartbeat_deadline;
    assert!(
        elapsed <= deadline && elapsed >= deadline - Duration::from_millis(5),
        "three attempts within the deadline: {elapsed:?}"
    );
    assert_eq!(err.kind(), TableErrorKind::Timeout, "{err}");
    assert!(err.to_string().contains(":Read:Rate? 1"), "{err}");
    assert_eq!(table.state(), TableState::Faulted);
    let notes = table.take_retries();
    assert_eq!(notes.len(), 3, "two retries and the give-up: {notes:#?}");
    // the heartbeat alone too
    let t0 = Instant::now();
    assert!(table.heartbeat().await.is_err());
    assert!(t0.elapsed() <= deadline);
}

#[tokio::test(start_paused = true)]
async fn interlock_opening_faults_the_driver_with_the_tables_text() {
    let (mut table, sim) = turning(10.0).await;
    sim.open_interlock();
    let err = table.sample().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault, "{err}");
    assert!(err.to_string().contains("201,\"Interlock open\""), "{err}");
    assert_eq!(table.state(), TableState::Faulted);
    // the abort profile brings it to rest with the servo off: that is rest too
    let rest = table.wait_stopped(Duration::from_secs(5)).await.unwrap();
    assert_eq!(rest.mode, TableMode::Off);
    assert_eq!(sim.mode(), SimMode::Off);
    assert_eq!(sim.actual_rate(Instant::now()), 0.0);
    assert_eq!(
        table.state(),
        TableState::Faulted,
        "rest does not clear the fault"
    );
}

#[tokio::test(start_paused = true)]
async fn wait_stopped_returns_only_at_rest() {
    let (mut table, sim) = turning(20.0).await;
    // the controlled stop decelerates at the 5 deg/s² last set: 4 s
    assert_eq!(
        table.stop_deadline(20.0),
        Duration::from_secs(11),
        "20/5 * 1.5 + 5 s"
    );
    let deadline = table.stop_deadline(20.0);
    table.stop().await.unwrap();
    let rest = table.wait_stopped(deadline).await.unwrap();
    // the instant it returns, the table really is at rest and in OFF
    let now = Instant::now();
    assert!(
        sim.actual_rate(now).abs() < 1e-3,
        "{}",
        sim.actual_rate(now)
    );
    assert_eq!(sim.mode(), SimMode::Off);
    assert!(sim.is_stopped());
    assert_eq!(rest.mode, TableMode::Off);
    assert!(rest.rate_dps.abs() <= 0.01, "{rest:?}");
    // not before the deceleration is over, and within one poll of it
    assert!(
        rest.waited >= Duration::from_secs(4) && rest.waited <= Duration::from_millis(4150),
        "{rest:?}"
    );
    assert_eq!(table.state(), TableState::Servoed);
}

#[tokio::test(start_paused = true)]
async fn wait_stopped_is_not_fooled_by_a_rate_passing_through_zero() {
    let (mut table, sim) = turning(5.0).await;
    // reversing through zero in RATE mode is not rest: the wait times out naming the rate
    table.set_rate(-5.0, 5.0).await.unwrap();
    tokio::time::sleep(Duration::from_millis(900)).await;
    let err = table
        .wait_stopped(Duration::from_millis(1500))
        .await
        .unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault);
    let msg = err.to_string();
    assert!(msg.contains("not at rest"), "{msg}");
    assert!(msg.contains("in mode RATE"), "{msg}");
    assert!(msg.contains("last measured -"), "{msg}");
    let_sim_run().await; // let the sim read the stop
    assert_eq!(sim.mode(), SimMode::Off, "the fault stopped the table");
}

#[tokio::test(start_paused = true)]
async fn wait_stopped_on_a_silent_table_fails_naming_the_last_rate() {
    let (mut table, sim) = turning(20.0).await;
    table.stop().await.unwrap();
    // answers for a while, then goes silent mid-deceleration
    let_sim_run().await;
    let silence = sim.clone();
    tokio::spawn(async move {
        tokio::time::sleep(Duration::from_millis(1050)).await;
        silence.set_silent(true);
    });
    let t0 = Instant::now();
    let err = table
        .wait_stopped(Duration::from_secs(11))
        .await
        .unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault, "{err}");
    let msg = err.to_string();
    assert!(msg.contains("could not confirm the table at rest"), "{msg}");
    // the last rate measured before the silence, mid-ramp: about 15 deg/s
    let last: f64 = msg
        .split("last measured ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|r| r.parse().ok())
        .unwrap_or_else(|| panic!("no rate in {msg}"));
    assert!((14.0..16.0).contains(&last), "{last} in {msg}");
    // asked again until the 11 s bound (a slow table would have answered meanwhile), and
    // not much past it: one query's timeout
    assert!(
        t0.elapsed() >= Duration::from_secs(11) && t0.elapsed() < Duration::from_secs(13),
        "{:?}",
        t0.elapsed()
    );
    assert_eq!(table.state(), TableState::Faulted);
    assert!(table.last_fault().unwrap().contains("last measured"));
}
