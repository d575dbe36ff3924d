//! Property ("fuzz") tests of the reply parsers and of the driver on hostile replies, run in
//! CI; the cargo-fuzz targets in `fuzz/` search the same ground for longer (see TESTING.md).
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use gyrocal_hp34401a::{
    DcvConfig, DriverOptions, Identity, Reading, Strategy, parse_error, parse_reading,
};
use gyrocal_link::{LinkError, Transport, show_bytes};
use proptest::prelude::*;

mod common;
use common::{IDN, NO_ERROR};

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn parsers_never_panic_on_any_text(s in any::<String>()) {
        if let Some(Reading::Volts(v)) = parse_reading(&s) {
            prop_assert!(v.is_finite());
        }
        let _ = parse_error(&s);
        if let Some(id) = Identity::parse(&s) {
            prop_assert!(id.model.eq_ignore_ascii_case("34401A"));
        }
    }

    #[test]
    fn parsers_never_panic_on_any_bytes(b in proptest::collection::vec(any::<u8>(), 0..64)) {
        let s = String::from_utf8_lossy(&b);
        let _ = parse_reading(&s);
        let _ = parse_error(&s);
        let _ = Identity::parse(&s);
    }

    #[test]
    fn readings_as_the_meter_formats_them_round_trip(
        neg in any::<bool>(),
        mant in 100_000_000u64..1_000_000_000,
        exp in -12i32..=3,
    ) {
        let digits = mant.to_string();
        let text = format!(
            "{}{}.{}E{}{:02}",
            if neg { '-' } else { '+' },
            &digits[..1],
            &digits[1..],
            if exp < 0 { '-' } else { '+' },
            exp.abs()
        );
        let want: f64 = text.parse().unwrap();
        prop_assert_eq!(parse_reading(&text), Some(Reading::Volts(want)));
    }

    #[test]
    fn near_valid_readings_never_panic(
        pos in 0usize..15,
        c in any::<char>(),
        cut in 0usize..16,
    ) {
        let good = "+1.00010310E+01";
        let mut chars: Vec<char> = good.chars().collect();
        chars[pos] = c;
        let mutated: String = chars.into_iter().collect();
        if let Some(Reading::Volts(v)) = parse_reading(&mutated) {
            prop_assert!(v.is_finite());
        }
        let _ = parse_reading(&good[..cut.min(good.len())]);
    }

    #[test]
    fn near_valid_error_entries_never_panic(code in any::<i64>(), msg in ".{0,40}", quote in any::<bool>()) {
        let q = if quote { "\"" } else { "" };
        let text = format!("{code:+},{q}{msg}{q}");
        if let Some(e) = parse_error(&text) {
            prop_assert_eq!(i64::from(e.code), code);
        }
    }

    /// A polled reading answered with anything: either a reading, or an error that names the
    /// bytes the meter sent.
    #[test]
    fn driver_errors_name_the_bytes_of_a_bad_reading(reply in "[^\n]{0,100}") {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .start_paused(true)
            .build()
            .unwrap();
        let result = rt.block_on(async {
            let link = Meter { last: String::new(), reading: Some(reply.clone()) };
            let options = DriverOptions { retries: 0, ..DriverOptions::default() };
            let mut dmm = common::ready(link, options, &DcvConfig::default()).await;
            dmm.acquire(1, Strategy::Poll).await
        });
        match parse_reading(&reply) {
            Some(r) => prop_assert_eq!(result.unwrap().readings, vec![r]),
            None => {
                let e = result.unwrap_err().to_string();
                prop_assert!(e.contains(&show_bytes(reply.as_bytes())), "{}", e);
            }
        }
    }
}

/// A meter that answers the driver's housekeeping correctly and `READ?` with `reading`.
struct Meter {
    last: String,
    reading: Option<String>,
}

impl Transport for Meter {
    fn describe(&self) -> &str {
        "prop-34401a"
    }
    async fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.last = String::from_utf8_lossy(bytes).trim_end().to_string();
        Ok(())
    }
    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        let q = self.last.rsplit(';').next().unwrap_or_default().to_string();
        match q.as_str() {
            "*IDN?" => Ok(IDN.into()),
            "SYST:ERR?" => Ok(NO_ERROR.into()),
            "*OPC?" => Ok("1".into()),
            "READ?" => match self.reading.take() {
                Some(r) => Ok(r),
                None => Err(LinkError::Timeout {
                    device: "prop-34401a".into(),
                    timeout: timeout.unwrap_or_default(),
                    partial: Vec::new(),
                }),
            },
            other => panic!("unexpected query {other:?}"),
        }
    }
    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        Ok(0)
    }
}
