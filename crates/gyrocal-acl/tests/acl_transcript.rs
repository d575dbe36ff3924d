//! Transcript tests: the exact bytes the ACL driver writes and how it reads the replies.

use std::time::Duration;

use gyrocal_acl::{AclConfig, AclTable};
use gyrocal_link::ScriptedTransport;
use gyrocal_table::{RateTable, TableErrorKind, TableState};

mod common;
use common::NO_ERROR;

const IDN: &str = "ACUTRONIC,ACUTROL3000,1234,3.1";

fn connected(script: ScriptedTransport) -> ScriptedTransport {
    script
        .query("*IDN?", IDN)
        .query(":System:Error?", NO_ERROR)
        .query(":Mode? 1", "OFF")
}

fn enabled(script: ScriptedTransport) -> ScriptedTransport {
    connected(script)
        .expect_line(":Interlock:Reset")
        .expect_line(":Interlock:Close 1")
        .expect_line(":Limit:Rate R,1,30.000000")
        .expect_line(":Mode:Rate 1")
        .query(":System:Error?", NO_ERROR)
}

#[tokio::test]
async fn table_transcript_connect_enable_rate_stop() {
    let script = enabled(ScriptedTransport::new("table"))
        .expect_line(":Limit:Acceleration R,1,5.000000")
        .expect_line(":Demand:Rate 1,-0.100000")
        .query(":System:Error?", NO_ERROR)
        .query(":Read:Rate? 1", "-0.100012")
        .query(":Read:Position? 1", "359.500000")
        .query(":Mode? 1", "RATE")
        .query("*STB?", "0")
        .expect_line(":Mode:Off 1")
        // after a controlled stop the next demand re-enters rate mode first
        .expect_line(":Mode:Rate 1")
        .expect_line(":Limit:Acceleration R,1,2.500000")
        .expect_line(":Demand:Rate 1,10.000000")
        .query(":System:Error?", NO_ERROR)
        .expect_line(":Interlock:Open 1");
    let mut table = AclTable::new(script, AclConfig::default());
    assert_eq!(table.state(), TableState::Disconnected);
    let id = table.connect().await.unwrap();
    assert_eq!(
        (id.manufacturer.as_str(), id.serial.as_str()),
        ("ACUTRONIC", "1234")
    );
    assert_eq!(table.state(), TableState::Connected);
    table.enable().await.unwrap();
    assert_eq!(table.state(), TableState::Servoed);
    table.set_rate(-0.1, 5.0).await.unwrap();
    assert_eq!(table.state(), TableState::Ramping { target: -0.1 });
    assert_eq!(table.read_rate().await.unwrap(), -0.100012);
    assert_eq!(table.read_position().await.unwrap(), 359.5);
    let status = table.status().await.unwrap();
    assert!(!status.interlock_event() && !status.error_queued());
    table.stop().await.unwrap();
    assert_eq!(table.state(), TableState::Stopping);
    table.set_rate(10.0, 2.5).await.unwrap();
    table.emergency_stop().await.unwrap();
    assert_eq!(table.state(), TableState::Stopping);
}

#[tokio::test]
async fn table_limits_are_refused_before_anything_is_sent() {
    // An empty script: any byte written fails the test.
    let mut table = AclTable::new(ScriptedTransport::new("table"), AclConfig::default());
    for (rate, acc) in [
        (30.001, 1.0),
        (-31.0, 1.0),
        (10.0, 0.0),
        (10.0, -1.0),
        (10.0, 10.5),
    ] {
        let err = table.set_rate(rate, acc).await.unwrap_err();
        assert_eq!(err.kind(), TableErrorKind::Limit, "{err}");
        assert!(
            err.to_string().contains("table: refused before sending"),
            "{err}"
        );
    }
    let err = table.set_rate(f64::NAN, 1.0).await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Limit);
    // inside the limits but not enabled: a state error, still nothing sent
    let err = table.set_rate(10.0, 1.0).await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::State, "{err}");
}

#[tokio::test]
async fn table_errors_are_surfaced_with_the_tables_text() {
    let script = connected(ScriptedTransport::new("table"))
        .expect_line(":Interlock:Reset")
        .expect_line(":Interlock:Close 1")
        .expect_line(":Limit:Rate R,1,30.000000")
        .expect_line(":Mode:Rate 1")
        .query(":System:Error?", "203,\"Fault latched: Rate trip\"")
        .query(":System:Error?", "201,\"Interlock open\"")
        .query(":System:Error?", NO_ERROR);
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    let err = table.enable().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Table);
    let msg = err.to_string();
    assert!(msg.contains("203,\"Fault latched: Rate trip\""), "{msg}");
    assert!(msg.contains(":Interlock:Close 1"), "{msg}");
    assert_eq!(table.state(), TableState::Connected);
}

#[tokio::test]
async fn table_latched_fault_in_a_sample_faults_the_driver_and_stops() {
    let script = enabled(ScriptedTransport::new("table"))
        .expect_line(":Limit:Acceleration R,1,5.000000")
        .expect_line(":Demand:Rate 1,20.000000")
        .query(":System:Error?", NO_ERROR)
        .query(":Read:Rate? 1", "9.990000")
        .query("*STB?", "129")
        .query(":System:Error?", "220,\"Tracking error limit exceeded\"")
        .query(":System:Error?", NO_ERROR)
        .expect_line(":Mode:Off 1");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    table.set_rate(20.0, 5.0).await.unwrap();
    table.start_recording();
    let err = table.sample().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault);
    assert!(
        err.to_string()
            .contains("220,\"Tracking error limit exceeded\""),
        "{err}"
    );
    assert_eq!(table.state(), TableState::Faulted);
    assert_eq!(
        table.stop_recording().count,
        0,
        "a faulted sample is not recorded"
    );
    assert!(table.last_fault().is_some());
}

#[tokio::test]
async fn table_silent_heartbeat_is_a_fault_after_retries_and_a_stop_attempt() {
    let script = connected(ScriptedTransport::new("table"))
        // three attempts (two retries): the reply is owed after the first, so the next two
        // first send the marker that gets the link back in step, which stays silent too
        .expect_line("*STB?")
        .silence()
        .expect_line("*IDN?")
        .silence()
        .expect_line("*IDN?")
        .silence()
        .expect_line(":Mode:Off 1")
        // the next query first gets back in step: a marker answered, a quiet window for the
        // earlier markers' replies (lost), then the query
        .query("*IDN?", IDN)
        .silence()
        .query("*STB?", "0");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    let err = table.heartbeat().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Timeout, "{err}");
    assert!(err.ends_run());
    assert_eq!(table.state(), TableState::Faulted);
    let notes = table.take_retries();
    assert_eq!(notes.len(), 3, "{notes:#?}");
    assert!(
        notes[0].starts_with("`*STB?`: no reply within") && notes[0].contains("(retry 1 of 2)"),
        "{notes:#?}"
    );
    assert!(notes[1].contains("(retry 2 of 2)"), "{notes:#?}");
    assert!(
        notes[2].contains("no usable reply in 3 attempts, gave up"),
        "{notes:#?}"
    );
    table.heartbeat().await.unwrap();
    assert!(table.take_retries().is_empty(), "taken once");
}

#[tokio::test]
async fn table_without_retries_faults_on_the_first_silence() {
    let script = connected(ScriptedTransport::new("table"))
        .expect_line("*STB?")
        .silence()
        .expect_line(":Mode:Off 1");
    let config = AclConfig {
        retries: 0,
        ..AclConfig::default()
    };
    let mut table = AclTable::new(script, config);
    table.connect().await.unwrap();
    let err = table.heartbeat().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Timeout, "{err}");
    assert_eq!(table.state(), TableState::Faulted);
    assert!(table.take_retries().is_empty());
}

#[tokio::test]
async fn table_garbled_status_byte_is_asked_again() {
    let script = connected(ScriptedTransport::new("table"))
        .query("*STB?", "1#9")
        .query("*STB?", "0");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    table.heartbeat().await.unwrap();
    assert_eq!(table.state(), TableState::Connected);
    let notes = table.take_retries();
    assert_eq!(
        notes,
        [
            "`*STB?`: unusable reply \"1#9\" (not a status byte (0..=255)); asked again (retry 1 of 2)"
        ]
    );
}

#[tokio::test]
async fn table_commands_are_never_resent_when_the_error_check_is_lost() {
    let script = enabled(ScriptedTransport::new("table"))
        .expect_line(":Limit:Acceleration R,1,5.000000")
        .expect_line(":Demand:Rate 1,20.000000")
        // the error-queue check loses its reply: back in step with the marker, only the query
        // is asked again
        .expect_line(":System:Error?")
        .silence()
        .query("*IDN?", IDN)
        .query(":System:Error?", NO_ERROR)
        // the same acceleration limit is not sent again
        .expect_line(":Demand:Rate 1,10.000000")
        // lost, and the table silent: the demand is still not repeated; the driver faults and
        // stops
        .expect_line(":System:Error?")
        .silence()
        .expect_line("*IDN?")
        .silence()
        .expect_line("*IDN?")
        .silence()
        .expect_line(":Mode:Off 1");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    table.set_rate(20.0, 5.0).await.unwrap();
    assert_eq!(table.state(), TableState::Ramping { target: 20.0 });
    let notes = table.take_retries();
    assert_eq!(notes.len(), 1, "{notes:#?}");
    assert!(
        notes[0].starts_with("`:System:Error?`: no reply"),
        "{notes:#?}"
    );
    assert!(
        notes[0].contains("a table error may be missing"),
        "a lost error-queue reply may have lost an entry: {notes:#?}"
    );
    let err = table.set_rate(10.0, 5.0).await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Timeout, "{err}");
    assert_eq!(table.state(), TableState::Faulted);
}

#[tokio::test]
async fn table_acceleration_limit_is_sent_only_when_it_changes_or_after_a_stop() {
    let script = enabled(ScriptedTransport::new("table"))
        .expect_line(":Limit:Acceleration R,1,5.000000")
        .expect_line(":Demand:Rate 1,20.000000")
        .query(":System:Error?", NO_ERROR)
        // same limit: the demand alone
        .expect_line(":Demand:Rate 1,10.000000")
        .query(":System:Error?", NO_ERROR)
        // a new limit is sent before the demand
        .expect_line(":Limit:Acceleration R,1,2.000000")
        .expect_line(":Demand:Rate 1,-10.000000")
        .query(":System:Error?", NO_ERROR)
        .expect_line(":Mode:Off 1")
        // after a stop the limit is never assumed: sent again
        .expect_line(":Mode:Rate 1")
        .expect_line(":Limit:Acceleration R,1,2.000000")
        .expect_line(":Demand:Rate 1,5.000000")
        .query(":System:Error?", NO_ERROR);
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    table.set_rate(20.0, 5.0).await.unwrap();
    table.set_rate(10.0, 5.0).await.unwrap();
    table.set_rate(-10.0, 2.0).await.unwrap();
    table.stop().await.unwrap();
    table.set_rate(5.0, 2.0).await.unwrap();
}

#[tokio::test]
async fn table_garbled_replies_name_the_bytes() {
    let script = connected(ScriptedTransport::new("table"))
        // asked three times; the error names the first reply
        .query(":Read:Rate? 1", "1.0e\u{1}")
        .query(":Read:Rate? 1", "")
        .query(":Read:Rate? 1", "?")
        .query("*IDN?", "ACUTRONIC,ACUTROL3000")
        .query("*IDN?", "ACUTRONIC")
        .query("*IDN?", "");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    let err = table.read_rate().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Link);
    let msg = err.to_string();
    assert!(msg.contains("\"1.0e\\x01\""), "{msg}");
    assert!(msg.contains("no usable reply in 3 attempts"), "{msg}");
    let err = table.connect().await.unwrap_err();
    assert!(err.to_string().contains("4 comma-separated"), "{err}");
    // the stale error queue is drained on connect: an unreadable entry is an error too
    let config = AclConfig {
        retries: 0,
        ..AclConfig::default()
    };
    let mut t2 = AclTable::new(
        ScriptedTransport::new("t2")
            .query("*IDN?", "A,B,C,D")
            .query(":System:Error?", "oops"),
        config,
    );
    let err = t2.connect().await.unwrap_err();
    assert!(err.to_string().contains("\"oops\""), "{err}");
    drop(table);
}

#[tokio::test]
async fn table_stop_handle_is_idempotent_and_works_from_another_task() {
    let script = enabled(ScriptedTransport::new("table"))
        .expect_line(":Mode:Off 1")
        .expect_line(":Mode:Off 1")
        .expect_line(":Interlock:Open 1")
        .expect_line(":Interlock:Open 1")
        .expect_line(":Mode:Off 1");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    let handle = table.stop_handle();
    let h2 = handle.clone();
    tokio::spawn(async move {
        h2.stop().await.unwrap();
        h2.stop().await.unwrap();
        h2.emergency_stop().await.unwrap();
    })
    .await
    .unwrap();
    assert_eq!(table.state(), TableState::Stopping);
    table.emergency_stop().await.unwrap();
    // a guard dropped without disarm stops the table (spawned on the runtime)
    let guard = handle.guard();
    drop(guard);
    tokio::time::sleep(Duration::from_millis(10)).await;
    handle.guard().disarm();
}

#[tokio::test]
async fn table_lost_then_unusable_replies_fault_the_driver() {
    let script = connected(ScriptedTransport::new("table"))
        .expect_line(":Read:Rate? 1")
        .silence()
        .query("*IDN?", IDN)
        .query(":Read:Rate? 1", "x")
        .query(":Read:Rate? 1", "y")
        // a link that lost a reply and never gave a usable one: fault and stop
        .expect_line(":Mode:Off 1");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    let err = table.read_rate().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Timeout, "the first miss: {err}");
    assert_eq!(table.state(), TableState::Faulted);
    let notes = table.take_retries();
    assert_eq!(notes.len(), 3, "{notes:#?}");
    assert!(notes[1].contains("unusable reply \"x\""), "{notes:#?}");
    assert!(
        notes[2].contains("unusable reply \"y\"") && notes[2].ends_with("gave up"),
        "{notes:#?}"
    );
}

#[tokio::test]
async fn table_late_replies_are_recognised_and_never_taken_for_the_next_query() {
    let script = ScriptedTransport::new("table")
        // the identity comes late: the marker sent to get back in step brings both replies,
        // which are read and dropped before *IDN? is asked again
        .expect_line("*IDN?")
        .silence()
        .expect_line("*IDN?")
        .reply(IDN)
        .reply(IDN)
        .query("*IDN?", IDN)
        .query(":System:Error?", NO_ERROR)
        .query(":Mode? 1", "OFF")
        // a rate read whose reply comes late, then the status byte: the late rate is read
        // before the marker's reply and dropped, never taken for the status byte
        .expect_line(":Read:Rate? 1")
        .silence()
        .expect_line("*IDN?")
        .reply("-0.000092")
        .reply(IDN)
        .query(":Read:Rate? 1", "0.000011")
        .query("*STB?", "0");
    let mut table = AclTable::new(script, AclConfig::default());
    table.connect().await.unwrap();
    assert_eq!(table.read_rate().await.unwrap(), 0.000011);
    table.heartbeat().await.unwrap();
    let notes = table.take_retries();
    assert!(
        notes
            .iter()
            .any(|n| n.contains("\"-0.000092\" to `:Read:Rate? 1`") && n.contains("discarded")),
        "{notes:#?}"
    );
}
