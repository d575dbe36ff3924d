//! Property ("fuzz") tests of both dialects against a controller that answers hostile bytes:
//! whatever comes back, the driver returns a reading or a typed error (garbled, silent,
//! instrument, setup, link), never panics, and never waits past its retries. In tokio's paused
//! clock, so each case is instant.

#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use gyrocal_chamber::{Chamber, ChamberErrorKind, Espec, EspecConfig, WatlowConfig, WatlowF4};
use gyrocal_link::memory_pair;
use proptest::prelude::*;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

fn block_on<F: std::future::Future>(f: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .unwrap()
        .block_on(f)
}

fn crc(data: &[u8]) -> [u8; 2] {
    let mut c: u32 = 0xFFFF;
    for &b in data {
        c ^= u32::from(b);
        for _ in 0..8 {
            let carry = c & 1;
            c >>= 1;
            if carry != 0 {
                c ^= 0xA001;
            }
        }
    }
    [(c & 0xFF) as u8, (c >> 8) as u8]
}

/// The kinds a hostile reply may give; anything else (or a panic) is a bug.
fn allowed(kind: ChamberErrorKind) -> bool {
    matches!(
        kind,
        ChamberErrorKind::Garbled
            | ChamberErrorKind::Timeout
            | ChamberErrorKind::Instrument
            | ChamberErrorKind::Setup
            | ChamberErrorKind::Link
    )
}

/// Connects and reads a Watlow F4 whose every reply is the next of `replies` (cycled).
fn watlow_against(replies: Vec<Vec<u8>>) {
    block_on(async move {
        let (host, mut device) = tokio::io::duplex(4096);
        let peer = tokio::spawn(async move {
            let mut n = 0usize;
            let mut req = [0u8; 8];
            while device.read_exact(&mut req).await.is_ok() {
                let reply = &replies[n % replies.len()];
                n += 1;
                if device.write_all(reply).await.is_err() {
                    break;
                }
            }
        });
        let mut f4 = WatlowF4::over_stream(host, "fuzz", 9600, WatlowConfig::default()).unwrap();
        let t0 = Instant::now();
        match f4.connect().await {
            Ok(_) => match f4.read().await {
                Ok(r) => assert!(r.air_c.is_finite()),
                Err(e) => assert!(allowed(e.kind()), "{e}"),
            },
            Err(e) => assert!(allowed(e.kind()), "{e}"),
        }
        // connect and read: at most 7 reads of 3 attempts of 1 s.
        assert!(
            t0.elapsed() <= Duration::from_secs(21),
            "{:?}",
            t0.elapsed()
        );
        drop(f4);
        peer.await.unwrap();
    });
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn watlow_survives_any_bytes(replies in prop::collection::vec(
        prop::collection::vec(any::<u8>(), 0..40), 1..6)) {
        watlow_against(replies);
    }

    /// Frames with a valid CRC and a hostile body: right slave and function, any byte count
    /// and data, or an exception with any code.
    #[test]
    fn watlow_survives_well_framed_nonsense(bodies in prop::collection::vec(
        (any::<bool>(), prop::collection::vec(any::<u8>(), 0..30)), 1..6)) {
        let replies = bodies
            .into_iter()
            .map(|(exception, body)| {
                let mut f = if exception { vec![1, 0x83] } else { vec![1, 0x03] };
                f.extend(body);
                let c = crc(&f);
                f.extend_from_slice(&c);
                f
            })
            .collect();
        watlow_against(replies);
    }

    #[test]
    fn espec_survives_any_lines(lines in prop::collection::vec(
        prop::collection::vec(any::<u8>(), 0..60), 1..6)) {
        block_on(async move {
            let (host, mut device) = memory_pair("fuzz");
            let peer = tokio::spawn(async move {
                let mut buf = [0u8; 64];
                let mut n = 0usize;
                // Every chunk the driver writes gets the next line back.
                while let Ok(k) = device.read(&mut buf).await {
                    if k == 0 {
                        break;
                    }
                    let mut line = lines[n % lines.len()].clone();
                    n += 1;
                    line.extend_from_slice(b"\r\n");
                    if device.write_all(&line).await.is_err() {
                        break;
                    }
                }
            });
            let mut e = Espec::over_transport(host, EspecConfig::default()).unwrap();
            match e.connect().await {
                Ok(_) => match e.read().await {
                    Ok(r) => assert!(r.air_c.is_finite()),
                    Err(err) => assert!(allowed(err.kind()), "{err}"),
                },
                Err(err) => assert!(allowed(err.kind()), "{err}"),
            }
            drop(e);
            peer.await.unwrap();
        });
    }
}
