//! The simulated table's wire protocol, byte for byte, in virtual time.

// Test helpers outside #[test] functions may unwrap too: a panic is a failed test.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use gyrocal_link::{StreamTransport, Transport, memory_pair};
use gyrocal_sim::table::{SimMode, SimTable, TableConfig, TableHandle};
use tokio::io::DuplexStream;
use tokio::time::Instant;

const T: Option<Duration> = Some(Duration::from_secs(1));

async fn q(link: &mut StreamTransport<DuplexStream>, line: &str) -> String {
    link.send_line(line).await.unwrap();
    link.read_line(T).await.unwrap()
}

async fn cmd(link: &mut StreamTransport<DuplexStream>, line: &str) {
    link.send_line(line).await.unwrap();
}

fn spawn(config: TableConfig) -> (StreamTransport<DuplexStream>, TableHandle) {
    let (link, dev) = memory_pair("sim");
    (link, SimTable::spawn(dev, config, 3))
}

#[tokio::test(start_paused = true)]
async fn table_protocol_error_queue_mode_rules_and_short_forms() {
    let (mut l, h) = spawn(TableConfig {
        rate_noise_std: 0.0,
        ripple_amplitude: 0.0,
        ..Default::default()
    });
    assert_eq!(
        q(&mut l, "*IDN?").await,
        "ACUTRONIC,ACUTROL3000,SIM0001,1.0"
    );
    assert_eq!(q(&mut l, ":System:Error?").await, "0,\"No error\"");
    assert_eq!(q(&mut l, ":mode? 1").await, "OFF");
    // a demand with the interlock open is refused
    cmd(&mut l, ":D:R 1,10").await;
    assert_eq!(q(&mut l, "*STB?").await, "128");
    assert_eq!(q(&mut l, ":S:E?").await, "201,\"Interlock open\"");
    assert_eq!(q(&mut l, ":S:E?").await, "0,\"No error\"");
    cmd(&mut l, ":Bogus:Thing 1").await;
    assert_eq!(
        q(&mut l, ":SYSTEM:ERROR?").await,
        "-113,\"Undefined header\""
    );
    // enable, rate mode; the acceleration limit starts at 0 and refuses demands
    cmd(&mut l, ":Interlock:Reset").await;
    cmd(&mut l, ":I:C 1").await;
    cmd(&mut l, ":Mode:Rate 1").await;
    cmd(&mut l, ":Demand:Rate 1,10").await;
    assert_eq!(
        q(&mut l, ":S:E?").await,
        "202,\"Acceleration limit must be positive\""
    );
    cmd(&mut l, ":Limit:Acceleration R,1,0").await;
    assert_eq!(
        q(&mut l, ":S:E?").await,
        "202,\"Acceleration limit must be positive\""
    );
    // a chain within one subsystem; a rate demand above the rate limit is refused, not clipped
    cmd(&mut l, ":Limit:Acceleration R,1,5;Rate R,1,15").await;
    cmd(&mut l, ":Demand:Rate 1,20").await;
    assert_eq!(q(&mut l, ":S:E?").await, "-222,\"Data out of range\"");
    assert_eq!(h.demanded_rate(), 0.0);
    let t0 = Instant::now();
    cmd(&mut l, ":Demand:Rate 1,-10").await;
    assert_eq!(q(&mut l, ":S:E?").await, "0,\"No error\"");
    assert_eq!(q(&mut l, ":Mode? 1").await, "RATE");
    tokio::time::sleep_until(t0 + Duration::from_secs(1)).await;
    assert_eq!(q(&mut l, ":Read:Rate? 1").await, "-5.000000");
    // position: -2.5 deg after 1 s of a 5 deg/s^2 ramp, wrapped into [0, 360)
    assert_eq!(q(&mut l, ":R:P? 1").await, "357.500000");
    tokio::time::sleep_until(t0 + Duration::from_secs(2 + 36)).await;
    // 10 deg after the ramp, then 36 s at -10 deg/s = 370 deg: -370 wraps to 350
    assert_eq!(q(&mut l, ":Read:Position? 1").await, "350.000000");
    assert_eq!(q(&mut l, ":Read:Rate? 1").await, "-10.000000");
    // controlled stop: smooth, at the acceleration limit
    cmd(&mut l, ":Mode:Off 1").await;
    assert_eq!(q(&mut l, ":Mode? 1").await, "OFF");
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert_eq!(q(&mut l, ":Read:Rate? 1").await, "-5.000000");
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert!(h.is_stopped());
    assert_eq!(q(&mut l, "*STB?").await, "0");
}

#[tokio::test(start_paused = true)]
async fn table_protocol_latched_fault_needs_a_reset() {
    let (mut l, h) = spawn(TableConfig {
        trip_rate: 12.0,
        ..Default::default()
    });
    for c in [
        ":Interlock:Reset",
        ":Interlock:Close 1",
        ":Mode:Rate 1",
        ":Limit:Acceleration R,1,4",
    ] {
        cmd(&mut l, c).await;
    }
    cmd(&mut l, ":Demand:Rate 1,20").await;
    // the trip latches at 12 deg/s, 3 s into the ramp, then the abort profile stops the table
    tokio::time::sleep(Duration::from_millis(3100)).await;
    assert_eq!(q(&mut l, "*STB?").await, "129");
    assert_eq!(h.mode(), SimMode::Abort);
    let err = q(&mut l, ":S:E?").await;
    assert!(err.starts_with("210,\"Rate trip: 12.000 deg/s"), "{err}");
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert_eq!(q(&mut l, ":Mode? 1").await, "OFF");
    assert!(h.is_stopped());
    cmd(&mut l, ":Interlock:Close 1").await;
    assert!(
        q(&mut l, ":S:E?")
            .await
            .starts_with("203,\"Fault latched: Rate trip")
    );
    cmd(&mut l, ":Interlock:Reset").await;
    assert_eq!(q(&mut l, "*STB?").await, "0");
    cmd(&mut l, ":Interlock:Close 1").await;
    assert_eq!(q(&mut l, "*STB?").await, "0"); // a round trip: the command was executed
    assert!(h.interlock_closed());
    // silence: nothing is answered or executed
    h.set_silent(true);
    l.send_line("*IDN?").await.unwrap();
    assert!(l.read_line(T).await.is_err());
    h.set_silent(false);
    l.discard_input().await.unwrap();
    assert_eq!(q(&mut l, "*STB?").await, "0");
    h.shutdown();
    assert!(l.read_line(T).await.is_err());
}
