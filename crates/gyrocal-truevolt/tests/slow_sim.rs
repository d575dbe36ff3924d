//! A Truevolt whose replies come late, and one whose LAN port refuses connections while it is
//! off, against the simulated Truevolt in virtual time (the `slow` fault of `gyrocal sim`):
//! a late reply is thrown away (never taken for another query's), the deadlines adapt to a
//! meter that is slow but alive, a meter too slow for them fails with a message that says
//! so, and a refused connection gets the same come-back window as a silent meter.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::sync::Arc;
use std::time::Duration;

use gyrocal_link::{Connector, SocketTransport};
use gyrocal_meter::{Acquired, ErrorKind, Measured, MeterError, Multimeter};
use gyrocal_sim::dmm::{DmmHandle, Fault};
use gyrocal_sim::truevolt::TruevoltConfig;
use gyrocal_truevolt::{Acquisition, Model, TruevoltMeter, TruevoltOptions};
use tokio::time::Instant;

mod common;
use common::slow_meter::{dcv, step};
use common::{VOLTS, refused, sim_truevolt};

async fn ready_with(
    acquisition: Acquisition,
    connector: impl FnOnce(Connector) -> Connector,
) -> (TruevoltMeter<SocketTransport>, DmmHandle) {
    let (link, handle) = sim_truevolt(TruevoltConfig::default(), connector).await;
    let options = TruevoltOptions {
        acquisition,
        ..TruevoltOptions::new(Model::M34461A)
    };
    let mut m = TruevoltMeter::new(link, options);
    m.connect().await.unwrap();
    m.configure(&dcv()).await.unwrap();
    (m, handle)
}

async fn ready(acquisition: Acquisition) -> (TruevoltMeter<SocketTransport>, DmmHandle) {
    ready_with(acquisition, |c| c).await
}

/// Every reading is the meter's input (within the simulated Truevolt's noise): no other
/// reply (`1` of `*OPC?`, an error-queue entry, an identity) was taken for readings, and none
/// is missing or extra.
fn all_readings(acq: &Acquired, n: usize) {
    common::slow_meter::all_readings(acq, n, VOLTS, 1e-3);
}

/// The 34461A: every reply 2.5 s late, in memory mode and in stream mode. The first
/// step's late reply is thrown away, the deadlines widen, and from then on every step is
/// measured at the first attempt; nothing is reconnected again and again.
#[tokio::test(start_paused = true)]
async fn replies_2_5_s_late_are_recognised_and_the_deadlines_adapt_in_memory_and_stream_modes() {
    for acquisition in [Acquisition::Memory, Acquisition::Stream] {
        let (mut m, h) = ready(acquisition).await;
        h.inject(Fault::Slow {
            delay_s: 2.5,
            replies: None,
        });
        let first = step(&mut m, 50).await;
        all_readings(&first, 50);
        assert_eq!(first.retries, 1, "{acquisition:?}: {:?}", first.notes);
        let note = &first.notes[0];
        assert!(
            note.contains("the meter answers slowly: the reply came")
                && note.contains("thrown away; reply deadlines widened by"),
            "{acquisition:?}: {note}"
        );
        assert!(!note.contains("re-established"), "{acquisition:?}: {note}");
        assert!(m.reply_delay() > Duration::ZERO);
        let clears = h.stats().device_clears;
        for _ in 0..4 {
            let later = step(&mut m, 50).await;
            all_readings(&later, 50);
            assert_eq!(later.retries, 0, "{acquisition:?}: {:?}", later.notes);
        }
        let st = h.stats();
        assert_eq!(
            st.device_clears, clears,
            "{acquisition:?}: no more reconnects"
        );
        assert!(st.late_replies > 10, "{acquisition:?}: {}", st.late_replies);
        assert!(st.error_queue.is_empty(), "{:?}", st.error_queue);
        assert_eq!(st.power_cycles, 0);
    }
}

/// A meter that was slow and then answers later than any deadline the driver allows: the
/// measurement fails within the documented bounds (the late-reply wait, then the 30 s
/// come-back window), and the message says the meter answers slowly, not that it was
/// power-cycled.
#[tokio::test(start_paused = true)]
async fn a_meter_too_slow_for_the_widest_deadlines_fails_in_bounded_time_naming_slow_replies() {
    for acquisition in [Acquisition::Memory, Acquisition::Stream] {
        let (mut m, h) = ready(acquisition).await;
        h.inject(Fault::Slow {
            delay_s: 2.5,
            replies: None,
        });
        all_readings(&step(&mut m, 50).await, 50);
        // now far slower: 60 s, beyond the widest deadline (3 s + 5 s)
        h.inject(Fault::Slow {
            delay_s: 60.0,
            replies: None,
        });
        let t0 = Instant::now();
        let e = match m.measure(50, true).await {
            Ok(Measured::Pending(p)) => m.collect(p).await.unwrap_err(),
            Ok(Measured::Complete(_)) => panic!("{acquisition:?}: measured at 60 s a reply"),
            Err(e) => e,
        };
        let took = t0.elapsed();
        let text = e.to_string();
        assert!(text.contains("tcp://sim:5025"), "{text}");
        assert!(
            text.contains("the meter answers slowly: a reply came"),
            "{acquisition:?}: {text}"
        );
        assert!(!text.contains("power cycle"), "{text}");
        assert!(
            matches!(e.kind(), ErrorKind::Unreachable | ErrorKind::Other),
            "{:?}",
            e.kind()
        );
        // deadline + 3 s late-reply wait + 30 s come-back window, with room for the steps
        assert!(took < Duration::from_secs(60), "{acquisition:?}: {took:?}");
    }
}

/// The meter is switched off (a power cycle of 12 s) and its LAN port refuses connections
/// meanwhile, as a real one does: the driver keeps reconnecting within its 30 s come-back
/// window, as for a meter that accepts the connection and stays silent, and the measurement
/// completes (it used to fail at the first refusal, 1.7 s after the meter went away).
#[tokio::test(start_paused = true)]
async fn a_refused_connection_gets_the_same_come_back_window_as_a_silent_meter() {
    let powered = Arc::new(std::sync::Mutex::new(None::<gyrocal_sim::dmm::DmmInjector>));
    let probe = powered.clone();
    let refusals = Arc::new(std::sync::atomic::AtomicU32::new(0));
    let counted = refusals.clone();
    let (mut m, h) = ready_with(Acquisition::Stream, move |inner| {
        Arc::new(move || {
            let off = probe
                .lock()
                .unwrap()
                .as_ref()
                .is_some_and(|i| !i.stats().powered);
            if off {
                counted.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                return refused();
            }
            inner()
        })
    })
    .await;
    *powered.lock().unwrap() = Some(h.injector());
    h.inject_at_reading(100, Fault::PowerCycle { off_s: Some(12.0) });
    let t0 = Instant::now();
    let acq = step(&mut m, 300).await;
    all_readings(&acq, 300);
    assert!(refusals.load(std::sync::atomic::Ordering::SeqCst) >= 3);
    assert_eq!(acq.retries, 1, "{:?}", acq.notes);
    assert!(
        acq.notes[0].contains("the connection was lost") && acq.notes[0].contains("re-established"),
        "{:?}",
        acq.notes
    );
    assert!(t0.elapsed() > Duration::from_secs(12));
    assert_eq!(h.stats().power_cycles, 1);
}

/// A connection refused for longer than the come-back window: the error says the meter did
/// not come back within 30 s, and quotes the refusal.
#[tokio::test(start_paused = true)]
async fn a_connection_refused_for_good_fails_after_the_come_back_window() {
    let gone = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = gone.clone();
    let (mut m, h) = ready_with(Acquisition::Stream, move |inner| {
        Arc::new(move || {
            if flag.load(std::sync::atomic::Ordering::SeqCst) {
                return refused();
            }
            inner()
        })
    })
    .await;
    gone.store(true, std::sync::atomic::Ordering::SeqCst);
    h.inject_at_reading(
        100,
        Fault::PowerCycle {
            off_s: Some(1000.0),
        },
    );
    let t0 = Instant::now();
    let e = m.measure(300, false).await.unwrap_err();
    let took = t0.elapsed();
    assert_eq!(e.kind(), ErrorKind::Unreachable, "{e}");
    let text = e.to_string();
    assert!(text.contains("did not come back within 3"), "{text}");
    assert!(text.to_lowercase().contains("refused"), "{text}");
    assert!(
        took >= Duration::from_secs(30) && took < Duration::from_secs(45),
        "{took:?}"
    );
}
