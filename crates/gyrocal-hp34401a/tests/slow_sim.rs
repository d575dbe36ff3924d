//! A 34401A whose replies come late (the `slow` fault of `gyrocal sim`: its bytes are held
//! back on their way, as in a serial converter with a deep buffer, so a device clear does not
//! recall them), against the simulated meter over an in-memory pipe, in virtual time: the
//! late reply is recognised and thrown away, never taken as the next query's answer; the
//! deadlines adapt to a meter that is slow but alive; one too slow for them fails with a
//! message that says so.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use gyrocal_hp34401a::{DriverOptions, Hp34401aMeter, Strategy};
use gyrocal_link::{DynStream, StreamTransport};
use gyrocal_meter::{Acquired, ErrorKind, Measured, MeterError, Multimeter};
use gyrocal_sim::dmm::{DmmConfig, DmmHandle, Fault};
use gyrocal_sim::signal::Constant;
use tokio::time::Instant;

mod common;
use common::slow_meter::{dcv, step};
use common::{VOLTS, sim_dmm};

type Meter = Hp34401aMeter<StreamTransport<DynStream>>;

async fn ready(strategy: Strategy) -> (Meter, DmmHandle) {
    let (link, handle) = sim_dmm(DmmConfig::default(), Box::new(Constant(VOLTS)), 7);
    let mut m = Hp34401aMeter::new(link, DriverOptions::default(), strategy, 9600);
    m.connect().await.unwrap();
    m.configure(&dcv()).await.unwrap();
    (m, handle)
}

/// Every reading is the meter's input (within the simulated 34401A's noise): no other reply
/// (`1` of `*OPC?`, an error-queue entry, `*ESR?`'s number) was taken for readings, and none
/// is missing or extra.
fn all_readings(acq: &Acquired, n: usize) {
    common::slow_meter::all_readings(acq, n, VOLTS, 1e-5);
}

/// Every reply 2.5 s late, streamed (`READ?`) and in memory (`INIT;*OPC?`, `FETC?`): the
/// first step's late reply is thrown away with whatever was still on its way after the
/// device clear, the deadlines widen, and every later step is measured at the first attempt.
#[tokio::test(start_paused = true)]
async fn replies_2_5_s_late_are_recognised_and_the_deadlines_adapt_stream_and_memory() {
    for strategy in [Strategy::Stream, Strategy::Memory] {
        let (mut m, h) = ready(strategy).await;
        h.inject(Fault::Slow {
            delay_s: 2.5,
            replies: None,
        });
        let first = step(&mut m, 50).await;
        all_readings(&first, 50);
        assert_eq!(first.retries, 1, "{strategy:?}: {:?}", first.notes);
        let note = &first.notes[0];
        assert!(
            note.contains("the meter answers slowly: the reply came")
                && note.contains("thrown away; reply deadlines widened by"),
            "{strategy:?}: {note}"
        );
        assert!(!note.contains("re-established"), "{strategy:?}: {note}");
        assert!(m.driver().reply_delay() > Duration::ZERO);
        let clears = h.stats().device_clears;
        for _ in 0..4 {
            let later = step(&mut m, 50).await;
            all_readings(&later, 50);
            assert_eq!(later.retries, 0, "{strategy:?}: {:?}", later.notes);
        }
        let st = h.stats();
        assert_eq!(
            st.device_clears, clears,
            "{strategy:?}: no more device clears"
        );
        assert!(st.late_replies > 5, "{strategy:?}: {}", st.late_replies);
        // nothing the driver sent was refused or cut short: -410 Query INTERRUPTED, -420
        // Query UNTERMINATED would be in the queue
        assert!(st.error_queue.is_empty(), "{:?}", st.error_queue);
        assert_eq!(st.power_cycles, 0);
    }
}

/// Late replies for a few exchanges only (`dmm:slow@...x3/2s`): the retry does not take the
/// bytes still on their way for its own reply (they are drained until the link is quiet).
#[tokio::test(start_paused = true)]
async fn a_few_late_replies_are_drained_and_the_next_exchanges_match_their_queries() {
    for strategy in [Strategy::Stream, Strategy::Memory] {
        let (mut m, h) = ready(strategy).await;
        h.inject(Fault::Slow {
            delay_s: 2.0,
            replies: Some(3),
        });
        for _ in 0..3 {
            all_readings(&step(&mut m, 30).await, 30);
        }
        let st = h.stats();
        assert_eq!(st.late_replies, 3, "{strategy:?}");
        assert!(st.error_queue.is_empty(), "{:?}", st.error_queue);
    }
}

/// Slow, then slower than the widest deadline allows (60 s): the measurement fails within the
/// bounds (the late-reply wait and the 30 s come-back window), and the message names slow
/// replies, not a power cycle.
#[tokio::test(start_paused = true)]
async fn a_meter_too_slow_for_the_widest_deadlines_fails_in_bounded_time_naming_slow_replies() {
    for strategy in [Strategy::Stream, Strategy::Memory] {
        let (mut m, h) = ready(strategy).await;
        h.inject(Fault::Slow {
            delay_s: 2.5,
            replies: None,
        });
        all_readings(&step(&mut m, 50).await, 50);
        h.inject(Fault::Slow {
            delay_s: 60.0,
            replies: None,
        });
        let t0 = Instant::now();
        let e = match m.measure(50, true).await {
            Ok(Measured::Pending(p)) => m.collect(p).await.unwrap_err(),
            Ok(Measured::Complete(_)) => panic!("{strategy:?}: measured with 60 s replies"),
            Err(e) => e,
        };
        let took = t0.elapsed();
        let text = e.to_string();
        assert!(text.contains("sim-dmm"), "{text}");
        assert!(
            text.contains("the meter answers slowly: a reply came"),
            "{strategy:?}: {text}"
        );
        assert!(!text.contains("power cycle"), "{text}");
        let kind = MeterError::kind(&e);
        assert!(
            matches!(kind, ErrorKind::Unreachable | ErrorKind::Other),
            "{kind:?}: {text}"
        );
        assert!(took < Duration::from_secs(90), "{strategy:?}: {took:?}");
    }
}
