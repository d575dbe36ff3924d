//! The driver against the simulated Truevolt (its real wire protocol), in virtual time.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use gyrocal_link::SocketTransport;
use gyrocal_meter::{ErrorKind, Measured, MeterError, Multimeter, Reading};
use gyrocal_sim::dmm::{DmmHandle, Fault};
use gyrocal_sim::truevolt::{Personality, TruevoltConfig};
use gyrocal_truevolt::{Acquisition, Model, TruevoltMeter, TruevoltOptions};
use tokio::time::Instant;

mod common;
use common::sim_truevolt;
use common::slow_meter::dcv;

async fn bench(
    config: TruevoltConfig,
    options: TruevoltOptions,
) -> (TruevoltMeter<SocketTransport>, DmmHandle) {
    let (link, handle) = sim_truevolt(config, |c| c).await;
    (TruevoltMeter::new(link, options), handle)
}

async fn ready(
    model: Model,
    acquisition: Acquisition,
) -> (TruevoltMeter<SocketTransport>, DmmHandle) {
    let config = TruevoltConfig {
        model,
        ..TruevoltConfig::default()
    };
    let options = TruevoltOptions {
        acquisition,
        ..TruevoltOptions::new(model)
    };
    let (mut m, h) = bench(config, options).await;
    m.connect().await.unwrap();
    m.configure(&dcv()).await.unwrap();
    (m, h)
}

/// 10,000 readings: one INIT drained while it measures, on a 34461A (memory 10,000) and on a
/// 34460A (memory 1,000: the memory never overflows, it is drained while it fills). The step
/// takes what the timing model says, to the millisecond tokio's timer rounds to.
#[tokio::test(start_paused = true)]
async fn ten_thousand_readings_stream_on_a_34461a_and_a_34460a() {
    for model in [Model::M34461A, Model::M34460A] {
        let (mut m, h) = ready(model, Acquisition::Auto).await;
        let cost = m.timing().unwrap().cost(10_000, true);
        let t0 = Instant::now();
        let Measured::Complete(acq) = m.measure(10_000, true).await.unwrap() else {
            panic!("streaming never defers")
        };
        let elapsed = t0.elapsed();
        assert_eq!(acq.readings.len(), 10_000, "{model}");
        assert_eq!(acq.retries, 0);
        assert!(
            acq.readings
                .iter()
                .all(|r| matches!(r, Reading::Volts(v) if (v - 2.5).abs() < 1e-4))
        );
        let stats = h.stats();
        assert_eq!(stats.readings_taken, 10_000);
        assert!(stats.memory_points == 0, "everything removed");
        assert!(stats.error_queue.is_empty(), "{:?}", stats.error_queue);
        // 415 s of readings; the step waits ~1 ms after the last one
        let over = elapsed.as_secs_f64() - cost.in_step.as_secs_f64();
        assert!(
            over.abs() < 0.05,
            "{model}: elapsed {elapsed:?}, model {:?}",
            cost.in_step
        );
        let ratio = elapsed.as_secs_f64() / cost.bound.as_secs_f64();
        assert!(ratio < 1.0002, "{model}: ratio {ratio}");
        // no overflow: Questionable Data bit 14 clear
        assert_eq!(h.stats().power_cycles, 0);
    }
}

#[tokio::test(start_paused = true)]
async fn memory_mode_defers_its_last_fetch() {
    let (mut m, _h) = ready(Model::M34460A, Acquisition::Memory).await;
    let Measured::Pending(p) = m.measure(1_500, true).await.unwrap() else {
        panic!("the last part stays in the meter")
    };
    let acq = m.collect(p).await.unwrap();
    assert_eq!(acq.readings.len(), 1_500);
}

#[tokio::test(start_paused = true)]
async fn identity_cases_against_the_simulator() {
    // posing as a 34401A: accepted as the plan's model
    let config = TruevoltConfig {
        personality: Personality::Hp34401a,
        ..TruevoltConfig::default()
    };
    let (mut m, _h) = bench(config, TruevoltOptions::new(Model::M34461A)).await;
    let id = m.connect().await.unwrap();
    assert!(id.model.contains("posing as 34401A"), "{}", id.model);
    // another model than the plan's
    let config = TruevoltConfig {
        model: Model::M34465A,
        ..TruevoltConfig::default()
    };
    let (mut m, _h) = bench(config, TruevoltOptions::new(Model::M34461A)).await;
    let e = m.connect().await.unwrap_err();
    assert!(e.to_string().contains("a 34465A answered"), "{e}");
    // NPLC 0.06 is a 34465A's, refused by the 34461A itself too (-222)
    let (mut m, h) = ready(Model::M34461A, Acquisition::Auto).await;
    let _ = &mut m;
    assert!(h.stats().error_queue.is_empty());
}

/// A reply garbled at reading 100: recovered (reconnect, ABOR) and counted once.
#[tokio::test(start_paused = true)]
async fn a_garbled_reply_is_recovered_once() {
    let (mut m, h) = ready(Model::M34461A, Acquisition::Auto).await;
    h.inject_at_reading(100, Fault::Garble);
    let Measured::Complete(acq) = m.measure(500, false).await.unwrap() else {
        panic!()
    };
    assert_eq!(acq.readings.len(), 500);
    assert_eq!(acq.retries, 1, "{:?}", acq.notes);
    assert_eq!(acq.notes.len(), 1);
    assert!(h.stats().device_clears >= 2, "reconnected");
}

/// A power cycle at reading 200: the meter comes back with its *RST settings; the driver
/// re-establishes the link and measures the rest again.
#[tokio::test(start_paused = true)]
async fn a_power_cycle_is_survived() {
    let (mut m, h) = ready(Model::M34461A, Acquisition::Auto).await;
    h.inject_at_reading(200, Fault::PowerCycle { off_s: Some(3.0) });
    let Measured::Complete(acq) = m.measure(500, false).await.unwrap() else {
        panic!()
    };
    assert_eq!(acq.readings.len(), 500);
    assert_eq!(acq.retries, 1, "{:?}", acq.notes);
    assert!(acq.notes[0].contains("re-established"), "{:?}", acq.notes);
    assert_eq!(h.stats().power_cycles, 1);
    assert_eq!(h.stats().nplc, 1.0, "configuration sent again");
}

/// A meter that is gone for good: the run's error is Unreachable after the reconnect timeout.
#[tokio::test(start_paused = true)]
async fn a_meter_gone_for_good_is_unreachable() {
    let (mut m, h) = ready(Model::M34461A, Acquisition::Auto).await;
    h.inject_at_reading(50, Fault::Disconnect);
    let t0 = Instant::now();
    let e = m.measure(500, false).await.unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Unreachable, "{e}");
    assert!(t0.elapsed() < Duration::from_secs(60));
}
