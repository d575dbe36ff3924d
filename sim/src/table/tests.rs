//! Unit tests of the simulated table's injectable faults (interlock, lost, garbled and noisy
//! replies), over an in-memory pipe in virtual time.

#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_link::{ErrorKind, StreamTransport, Transport, memory_pair};
use tokio::io::DuplexStream;

use super::*;

const T: Option<Duration> = Some(Duration::from_secs(1));

type Link = StreamTransport<DuplexStream>;

async fn q(link: &mut Link, line: &str) -> String {
    link.send_line(line).await.unwrap();
    link.read_line(T).await.unwrap()
}

/// A table turning at 10 deg/s in RATE mode (reached after 1 s at 10 deg/s²).
async fn turning() -> (Link, TableHandle) {
    let (mut link, dev) = memory_pair("sim");
    let h = SimTable::spawn(dev, TableConfig::default(), 3);
    for c in [
        ":Interlock:Reset",
        ":Interlock:Close 1",
        ":Mode:Rate 1",
        ":Limit:Acceleration R,1,10",
        ":Demand:Rate 1,10",
    ] {
        link.send_line(c).await.unwrap();
    }
    assert_eq!(q(&mut link, ":System:Error?").await, "0,\"No error\"");
    tokio::time::sleep(Duration::from_secs(2)).await;
    assert!((h.actual_rate(Instant::now()) - 10.0).abs() < 1e-3);
    (link, h)
}

#[test]
fn faulty_replies_on_the_wire() {
    assert_eq!(faulty_reply("10.000000", None), b"10.000000\n");
    assert_eq!(faulty_reply("10.000000", Some(ReplyFault::Drop)), b"");
    assert_eq!(
        faulty_reply("-10.000000", Some(ReplyFault::Garble)),
        b"-#0.000000\n"
    );
    assert_eq!(faulty_reply("OFF", Some(ReplyFault::Garble)), b"#FF\n");
    assert_eq!(faulty_reply("", Some(ReplyFault::Garble)), b"#\n");
    assert_eq!(
        faulty_reply("129", Some(ReplyFault::Noise)),
        b"\xff129\n".to_vec()
    );
}

#[tokio::test(start_paused = true)]
async fn interlock_opening_aborts_latches_and_reports() {
    let (mut link, h) = turning().await;
    h.open_interlock();
    assert_eq!(h.mode(), SimMode::Abort);
    assert!(!h.interlock_closed());
    assert_eq!(h.demanded_rate(), 0.0);
    // interlock event (bit 0) and a queued error (bit 7)
    assert_eq!(q(&mut link, "*STB?").await, "129");
    assert_eq!(q(&mut link, ":Mode? 1").await, "ABORT");
    assert_eq!(
        q(&mut link, ":System:Error?").await,
        "201,\"Interlock open\""
    );
    // the abort profile stops 10 deg/s at 100 deg/s² in 0.1 s, then the servo is off
    tokio::time::sleep(Duration::from_millis(150)).await;
    assert_eq!(q(&mut link, ":Mode? 1").await, "OFF");
    assert_eq!(h.actual_rate(Instant::now()), 0.0);
    assert!(h.is_stopped());
    assert_eq!(q(&mut link, "*STB?").await, "1");
    // latched: closing needs a reset first
    link.send_line(":Interlock:Close 1").await.unwrap();
    assert!(
        q(&mut link, ":System:Error?")
            .await
            .starts_with("203,\"Fault latched: Interlock open")
    );
    link.send_line(":Interlock:Reset").await.unwrap();
    link.send_line(":Interlock:Close 1").await.unwrap();
    assert_eq!(q(&mut link, "*STB?").await, "0");
    assert!(h.interlock_closed());
    // an interlock opened by command sets the event bit too; a hardware opening of an
    // interlock already open changes nothing
    link.send_line(":Interlock:Open 1").await.unwrap();
    assert_eq!(q(&mut link, "*STB?").await, "1");
    link.send_line(":Interlock:Reset").await.unwrap();
    h.open_interlock();
    assert_eq!(q(&mut link, "*STB?").await, "0");
}

#[tokio::test(start_paused = true)]
async fn interlock_armed_at_a_demand_opens_halfway_through_its_ramp() {
    let (mut link, h) = turning().await;
    h.arm_at_demand(2, DemandFault::Interlock);
    // from 10 to 30 deg/s at 10 deg/s²: 2 s, so the interlock opens at 20 deg/s after 1 s
    link.send_line(":Demand:Rate 1,30").await.unwrap();
    tokio::time::sleep(Duration::from_millis(990)).await;
    assert_eq!(h.mode(), SimMode::Rate);
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert_eq!(h.mode(), SimMode::Abort);
    assert_eq!(h.fault().as_deref(), Some("Interlock open"));
    assert_eq!(q(&mut link, "*STB?").await, "129");
}

#[tokio::test(start_paused = true)]
async fn dropped_replies_are_executed_but_never_sent() {
    let (mut link, h) = turning().await;
    // a bad command queues an error; its reply-less line does not use up a reply fault
    link.send_line(":Bogus").await.unwrap();
    h.inject_reply_faults(ReplyFault::Drop, 2);
    assert_eq!(h.pending_reply_faults(), 2);
    link.send_line(":System:Error?").await.unwrap();
    let err = link.read_line(T).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Timeout);
    link.send_line("*STB?").await.unwrap();
    assert_eq!(
        link.read_line(T).await.unwrap_err().kind(),
        ErrorKind::Timeout
    );
    assert_eq!(h.pending_reply_faults(), 0);
    // the lost `:System:Error?` reply took its entry with it: the queue is empty now
    assert_eq!(q(&mut link, "*STB?").await, "0");
    assert_eq!(q(&mut link, ":System:Error?").await, "0,\"No error\"");
}

#[tokio::test(start_paused = true)]
async fn garbled_replies_do_not_parse() {
    let (mut link, h) = turning().await;
    h.inject_reply_faults(ReplyFault::Garble, 3);
    let rate = q(&mut link, ":Read:Rate? 1").await;
    assert!(rate.contains('#'), "{rate}");
    assert!(rate.parse::<f64>().is_err(), "{rate}");
    assert_eq!(q(&mut link, "*STB?").await, "#");
    assert_eq!(q(&mut link, ":Mode? 1").await, "#ATE");
    // only three
    assert_eq!(q(&mut link, ":Mode? 1").await, "RATE");
}

#[tokio::test(start_paused = true)]
async fn noise_byte_prefixes_the_reply() {
    let (mut link, h) = turning().await;
    h.inject_reply_faults(ReplyFault::Noise, 1);
    link.send_line("*STB?").await.unwrap();
    match link.read_line(T).await.unwrap_err() {
        gyrocal_link::LinkError::Garbled { bytes, .. } => assert_eq!(bytes, b"\xff0"),
        e => panic!("expected a garbled line, got {e}"),
    }
    assert_eq!(q(&mut link, "*STB?").await, "0");
}

#[tokio::test(start_paused = true)]
async fn reply_faults_armed_at_a_demand_hit_the_replies_after_it() {
    let (mut link, h) = turning().await;
    h.arm_at_demand(2, DemandFault::Reply(ReplyFault::Drop, 1));
    assert_eq!(q(&mut link, "*STB?").await, "0");
    link.send_line(":Demand:Rate 1,5").await.unwrap();
    // the demand was executed, the reply to the next query is lost
    link.send_line(":System:Error?").await.unwrap();
    assert!(link.read_line(T).await.is_err());
    assert_eq!(h.demands_seen(), 2);
    assert_eq!(h.demanded_rate(), 5.0);
    assert_eq!(q(&mut link, ":System:Error?").await, "0,\"No error\"");
}
