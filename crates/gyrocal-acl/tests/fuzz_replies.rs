//! Property ("fuzz") tests of the ACL driver against a table that answers hostile lines, run
//! in CI. The ACL reply parsers are private, so the driver is exercised whole (in tokio's
//! paused clock); the cargo-fuzz target `acl_replies` in `fuzz/` does the same for longer.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::collections::VecDeque;
use std::time::Duration;

use gyrocal_acl::{AclConfig, AclTable};
use gyrocal_link::{LinkError, Transport, show_bytes};
use gyrocal_table::{RateTable, SettleCriteria};
use proptest::prelude::*;

/// Answers every read with the next scripted line, whatever was asked; a timeout after them.
struct Replies(VecDeque<String>);

impl Transport for Replies {
    fn describe(&self) -> &str {
        "prop-table"
    }
    async fn write_raw(&mut self, _bytes: &[u8]) -> Result<(), LinkError> {
        Ok(())
    }
    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        self.0.pop_front().ok_or_else(|| LinkError::Timeout {
            device: "prop-table".into(),
            timeout: timeout.unwrap_or_default(),
            partial: Vec::new(),
        })
    }
    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        Ok(0)
    }
}

fn block_on<F: std::future::Future>(f: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .start_paused(true)
        .build()
        .unwrap()
        .block_on(f)
}

const IDN: &str = "ACUTRONIC,ACUTROL3000,SIM0001,1.0";

mod common;
use common::NO_ERROR;

/// A reply that is either arbitrary or one the table could plausibly send.
fn reply() -> impl Strategy<Value = String> {
    prop_oneof![
        "[^\n]{0,40}",
        Just(NO_ERROR.to_string()),
        Just("201,\"Interlock open\"".to_string()),
        Just("OFF".to_string()),
        Just("RATE".to_string()),
        Just("ABORT".to_string()),
        Just("1".to_string()),
        Just("129".to_string()),
        (-50.0f64..50.0).prop_map(|v| format!("{v:.6}")),
        Just("NaN".to_string()),
        Just("1e999".to_string()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    /// Whatever the table answers, every driver call returns (an error is fine).
    #[test]
    fn driver_never_panics_on_any_replies(replies in proptest::collection::vec(reply(), 0..60)) {
        block_on(async move {
            let mut table = AclTable::new(Replies(replies.into()), AclConfig::default());
            let criteria = SettleCriteria { timeout: Duration::from_secs(3), ..SettleCriteria::default() };
            if table.connect().await.is_ok() && table.enable().await.is_ok()
                && table.set_rate(10.0, 5.0).await.is_ok()
            {
                let _ = table.wait_at_rate(&criteria).await;
            }
            let _ = table.read_rate().await;
            let _ = table.read_position().await;
            let _ = table.status().await;
            let _ = table.heartbeat().await;
            let _ = table.stop().await;
            let _ = table.wait_stopped(Duration::from_secs(1)).await;
            let _ = table.emergency_stop().await;
        });
    }

    /// A bad `*IDN?` reply is refused with its bytes in the message.
    #[test]
    fn bad_identity_is_named(idn in "[^\n]{0,60}") {
        let replies = VecDeque::from([idn.clone(), NO_ERROR.to_string(), "OFF".to_string()]);
        let r = block_on(async move { AclTable::new(Replies(replies), AclConfig::default()).connect().await });
        if idn.split(',').count() != 4 {
            let e = r.unwrap_err().to_string();
            prop_assert!(e.contains(&show_bytes(idn.as_bytes())), "{}", e);
        }
    }

    /// A bad `:Mode? 1` reply is refused with its bytes in the message.
    #[test]
    fn bad_mode_is_named(mode in "[^\n]{0,30}") {
        let replies = VecDeque::from([IDN.to_string(), NO_ERROR.to_string(), mode.clone()]);
        let r = block_on(async move { AclTable::new(Replies(replies), AclConfig::default()).connect().await });
        let known = ["OFF", "RATE", "POSITION", "POS", "ABORT"]
            .contains(&mode.trim().to_ascii_uppercase().as_str());
        if !known {
            let e = r.unwrap_err().to_string();
            prop_assert!(e.contains(&show_bytes(mode.as_bytes())), "{}", e);
        }
    }

    /// A bad rate reading is refused with its bytes in the message.
    #[test]
    fn bad_rate_is_named(rate in "[^\n]{0,30}") {
        let replies = VecDeque::from([IDN.to_string(), NO_ERROR.to_string(), "OFF".to_string(), rate.clone()]);
        let r = block_on(async move {
            let mut t = AclTable::new(Replies(replies), AclConfig::default());
            t.connect().await.unwrap();
            t.read_rate().await
        });
        match rate.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => prop_assert_eq!(r.unwrap(), v),
            _ => {
                let e = r.unwrap_err().to_string();
                prop_assert!(e.contains(&show_bytes(rate.as_bytes())), "{}", e);
            }
        }
    }
}
