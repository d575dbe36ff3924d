//! Transcript tests: the exact bytes the experimental Ideal Aerosmith dialect writes and how it
//! reads replies that end with a `>` prompt.

use gyrocal_aerosmith::{
    AerosmithConfig, AerosmithTable, LineEnding, McoPolarity, NO_CODE, RateUnits,
};
use gyrocal_link::ScriptedTransport;
use gyrocal_table::{RateTable, TableError, TableErrorKind, TableMode, TableState};

mod common;
use common::aerosmith;

/// Expects `command` + CR and answers `reply` (which ends with the prompt).
fn q(script: ScriptedTransport, command: &str, reply: &str) -> ScriptedTransport {
    script
        .expect_raw(format!("{command}\r").as_bytes())
        .reply(reply)
}

fn connected(script: ScriptedTransport) -> ScriptedTransport {
    let script = q(script, "STA", "0\r>");
    q(script, "MCO0.0100", "1\r>")
}

fn enabled(script: ScriptedTransport) -> ScriptedTransport {
    q(connected(script), "SRV", ">")
}

#[tokio::test]
async fn aerosmith_transcript_connect_enable_rate_stop() {
    let script = enabled(ScriptedTransport::new("table"));
    let script = q(script, "ACL5.0000", ">");
    let script = q(script, "JOG-0.1000", ">");
    let script = q(script, "PVE", "-0.100012\r>");
    let script = q(script, "PPO", "\r\n359.5\r\n>");
    let script = q(script, "STA", "3\r>");
    // the stop does not wait for its prompt: the next exchange reads it first
    let script = script.expect_raw(b"STO\r").reply(">");
    let script = q(script, "ACL2.5000", ">");
    let script = q(script, "JOG10.0000", ">");
    // no interlock command: the emergency stop is STO too
    let script = script.expect_raw(b"STO\r");
    let mut table = aerosmith(script);
    let id = table.connect().await.unwrap();
    assert_eq!(id.manufacturer, "Ideal Aerosmith");
    assert_eq!(table.state(), TableState::Connected);
    assert_eq!(table.capabilities().dialect, "aerosmith");
    table.enable().await.unwrap();
    assert_eq!(table.state(), TableState::Servoed);
    table.set_rate(-0.1, 5.0).await.unwrap();
    assert_eq!(table.state(), TableState::Ramping { target: -0.1 });
    assert_eq!(table.read_rate().await.unwrap(), -0.100012);
    assert_eq!(table.read_position().await.unwrap(), 359.5);
    let status = table.status().await.unwrap();
    assert_eq!(status.mode, TableMode::Rate);
    assert!(!status.interlock_event());
    table.stop().await.unwrap();
    assert_eq!(table.state(), TableState::Stopping);
    table.set_rate(10.0, 2.5).await.unwrap();
    table.emergency_stop().await.unwrap();
    assert_eq!(table.state(), TableState::Stopping);
    assert!(table.take_retries().is_empty());
}

#[tokio::test]
async fn aerosmith_question_mark_is_a_table_error_and_limits_send_nothing() {
    let script = enabled(ScriptedTransport::new("table"));
    let script = q(script, "ACL5.0000", ">");
    let script = q(script, "JOG10.0000", "?\r>");
    let mut table = aerosmith(script);
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    // client-side limits: refused before a byte is sent
    for (rate, acc) in [(30.5, 1.0), (10.0, 0.0), (10.0, 11.0)] {
        let err = table.set_rate(rate, acc).await.unwrap_err();
        assert_eq!(err.kind(), TableErrorKind::Limit, "{err}");
    }
    let err = table.set_rate(10.0, 5.0).await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Table, "{err}");
    let TableError::Table { code, command, .. } = &err else {
        panic!("{err}")
    };
    assert_eq!((*code, command.as_str()), (NO_CODE, "JOG10.0000"));
    // a refused demand does not fault the driver
    assert_eq!(table.state(), TableState::Servoed);
}

#[tokio::test]
async fn aerosmith_fault_bit_in_a_sample_faults_the_driver_and_stops() {
    let script = enabled(ScriptedTransport::new("table"));
    let script = q(script, "ACL5.0000", ">");
    let script = q(script, "JOG20.0000", ">");
    let script = q(script, "PVE", "9.990000\r>");
    let script = q(script, "STA", "5\r>");
    let script = script.expect_raw(b"STO\r");
    let mut table = aerosmith(script);
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    table.set_rate(20.0, 5.0).await.unwrap();
    let err = table.sample().await.unwrap_err();
    assert_eq!(err.kind(), TableErrorKind::Fault);
    assert!(err.to_string().contains("status word 5"), "{err}");
    assert_eq!(table.state(), TableState::Faulted);
}

#[tokio::test]
async fn aerosmith_lost_and_garbled_replies_are_asked_again() {
    let script = enabled(ScriptedTransport::new("table"));
    // the reply comes late: its prompt is owed, read before the next exchange and thrown
    // away, never taken as the next PVE's
    let script = script.expect_raw(b"PVE\r").silence().reply("0.400000\r>");
    let script = q(script, "PVE", "#.5\r>");
    let script = q(script, "PVE", "0.500000\r>");
    let mut table = aerosmith(script);
    table.connect().await.unwrap();
    table.enable().await.unwrap();
    assert_eq!(table.read_rate().await.unwrap(), 0.5);
    let notes = table.take_retries();
    assert_eq!(notes.len(), 3, "{notes:?}");
    assert!(notes[0].contains("`PVE`: no reply"), "{notes:?}");
    assert!(
        notes[1].contains("late reply \"0.400000\\r\" to `PVE`") && notes[1].contains("discarded"),
        "{notes:?}"
    );
    assert!(notes[2].contains("unusable reply"), "{notes:?}");
}

#[tokio::test]
async fn aerosmith_options_crlf_per_minute_and_mco_polarity() {
    let config = AerosmithConfig {
        line_ending: LineEnding::CrLf,
        rate_units: RateUnits::DegPerMin,
        mco_polarity: McoPolarity::ZeroIsComplete,
        ..AerosmithConfig::default()
    };
    let script = ScriptedTransport::new("table")
        .expect_raw(b"STA\r\n")
        .reply("1\r\n>")
        .expect_raw(b"MCO0.6000\r\n")
        .reply("0\r\n>")
        .expect_raw(b"SRV\r\n")
        .reply(">")
        .expect_raw(b"ACL5.0000\r\n")
        .reply(">")
        .expect_raw(b"JOG600.0000\r\n")
        .reply(">")
        .expect_raw(b"PVE\r\n")
        .reply("600.000000\r\n>");
    let mut table = AerosmithTable::new(script, config);
    table.connect().await.unwrap();
    assert_eq!(
        table.state(),
        TableState::Connected,
        "MCO 0 = complete: OFF"
    );
    table.enable().await.unwrap();
    table.set_rate(10.0, 5.0).await.unwrap();
    assert_eq!(table.read_rate().await.unwrap(), 10.0);
}
