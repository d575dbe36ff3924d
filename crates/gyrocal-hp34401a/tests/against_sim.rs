//! The driver against the simulated 34401A over an in-memory pipe, in virtual time.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::sync::{Arc, Mutex};
use std::time::Duration;

use gyrocal_hp34401a::{
    AutoZero, DcvConfig, DriverOptions, Error, ErrorKind, Hp34401a, LinkLoss, Reading, Strategy,
    Timing,
};
use gyrocal_sim::dmm::{DmmConfig, DmmHandle, Fault, LocalMode};
use gyrocal_sim::signal::{Constant, FnOfTime};
use tokio::time::Instant;

mod common;
use common::{Dmm, VOLTS, nplc1, ready, sim_dmm};

async fn bench_with(cfg: DmmConfig, config: &DcvConfig, volts: f64) -> (Dmm, DmmHandle) {
    let (link, handle) = sim_dmm(cfg, Box::new(Constant(volts)), 7);
    let mut dmm = Hp34401a::new(link, DriverOptions::default());
    let id = dmm.connect().await.unwrap();
    assert_eq!(id.raw, "HEWLETT-PACKARD,34401A,0,11-5-2");
    dmm.configure(config).await.unwrap();
    (dmm, handle)
}

async fn bench(config: &DcvConfig) -> (Dmm, DmmHandle) {
    bench_with(DmmConfig::default(), config, VOLTS).await
}

async fn timed(dmm: &mut Dmm, n: usize, s: Strategy) -> (Vec<Reading>, f64) {
    let t0 = Instant::now();
    let acq = dmm.acquire(n, s).await.unwrap();
    assert_eq!(acq.readings.len(), n);
    assert_eq!(acq.retries, 0);
    for r in &acq.readings {
        let v = r.volts().unwrap();
        assert!((v - 1.234_567).abs() < 1e-5, "{v}");
    }
    (acq.readings, t0.elapsed().as_secs_f64())
}

#[tokio::test(start_paused = true)]
async fn timing_500_readings_stream_memory_poll() {
    let cfg = nplc1();
    let (mut dmm, sim) = bench(&cfg).await;
    let (_, stream) = timed(&mut dmm, 500, Strategy::Stream).await;
    let (_, memory) = timed(&mut dmm, 500, Strategy::Memory).await;
    let (_, poll) = timed(&mut dmm, 500, Strategy::Poll).await;
    let doc = 0.020 + 500.0 * 0.0415; // arm + 500 readings of 41.5 ms
    let model = Timing::new(&cfg);
    println!(
        "500 readings, NPLC 1, 50 Hz, autozero on, 9600 baud (virtual seconds): \
         stream {stream:.3} (doc {doc:.3}, model {:.3}), memory {memory:.3} (model {:.3}), \
         poll {poll:.3} (model {:.3})",
        model.estimate(Strategy::Stream, 500).as_secs_f64(),
        model.estimate(Strategy::Memory, 500).as_secs_f64(),
        model.estimate(Strategy::Poll, 500).as_secs_f64(),
    );
    assert!(
        (stream - doc).abs() / doc < 0.01,
        "stream {stream} vs {doc}"
    );
    assert!(poll > stream * 1.5, "poll {poll} vs stream {stream}");
    for (got, s) in [
        (stream, Strategy::Stream),
        (memory, Strategy::Memory),
        (poll, Strategy::Poll),
    ] {
        let want = model.estimate(s, 500).as_secs_f64();
        assert!(
            (got - want).abs() / want < 0.01,
            "{s:?}: {got} vs model {want}"
        );
    }
    assert_eq!(sim.readings_taken(), 1500);
    let st = sim.stats();
    assert!(st.error_queue.is_empty(), "{:?}", st.error_queue);
    assert_eq!(st.errors_raised, 0);
    assert!(st.max_input_backlog < 100, "{}", st.max_input_backlog);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn memory_2000_readings_in_4_bursts() {
    let cfg = DcvConfig {
        nplc: 0.2,
        autozero: AutoZero::Off,
        ..nplc1()
    };
    let (mut dmm, sim) = bench(&cfg).await;
    let seen = Arc::new(Mutex::new(Vec::new()));
    let s2 = seen.clone();
    dmm.set_progress(move |p| s2.lock().unwrap().push(p.done));
    let lines_before = sim.stats().lines_seen;
    let (r, secs) = timed(&mut dmm, 2000, Strategy::Memory).await;
    assert_eq!(r.len(), 2000);
    let st = sim.stats();
    // 4 x (INIT;*OPC?, FETC?), and SAMP:COUN only when it changes: 512 for three bursts,
    // 464 for the last
    assert_eq!(st.lines_seen - lines_before, 10);
    assert_eq!(st.readings_taken, 2000);
    let seen = seen.lock().unwrap().clone();
    assert_eq!(seen.len(), 2000);
    assert_eq!(seen.last(), Some(&2000));
    let want = Timing::new(&cfg)
        .estimate(Strategy::Memory, 2000)
        .as_secs_f64();
    assert!((secs - want).abs() / want < 0.01, "{secs} vs {want}");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn auto_streams_when_the_wire_keeps_up_and_uses_memory_otherwise() {
    let (mut dmm, sim) = bench(&nplc1()).await;
    assert_eq!(
        dmm.acquire(20, Strategy::Auto).await.unwrap().strategy,
        Strategy::Stream
    );
    let fast = DcvConfig {
        nplc: 0.02,
        autozero: AutoZero::Off,
        ..nplc1()
    };
    dmm.configure(&fast).await.unwrap();
    let acq = dmm.acquire(600, Strategy::Auto).await.unwrap();
    assert_eq!(acq.strategy, Strategy::Memory);
    assert_eq!(acq.readings.len(), 600);
    // a stream at this rate is wire-bound: the meter's output buffer throttles it
    let (_, stream) = timed(&mut dmm, 600, Strategy::Stream).await;
    let wire = 600.0 * 16.0 * 11.0 / 9600.0;
    assert!(stream > wire * 0.99, "{stream} vs {wire}");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn split_burst_overlaps_with_other_work() {
    let (mut dmm, sim) = bench(&nplc1()).await;
    let b = dmm.arm_burst(100).await.unwrap();
    dmm.wait_burst(&b).await.unwrap();
    let t0 = Instant::now();
    let (readings, ()) = tokio::join!(dmm.fetch(&b), tokio::time::sleep(Duration::from_secs(1)));
    assert_eq!(readings.unwrap().len(), 100);
    // the fetch (about 1.8 s on the wire) hid the 1 s of "table motion"
    assert!(
        t0.elapsed() < Duration::from_millis(2000),
        "{:?}",
        t0.elapsed()
    );
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn signal_is_sampled_at_each_reading_time() {
    let ramp = FnOfTime::new(|t| t); // 1 V per second
    let cfg = DmmConfig {
        noise_v: 0.0,
        ..DmmConfig::default()
    };
    let (link, sim) = sim_dmm(cfg, Box::new(ramp), 1);
    let mut dmm = ready(link, DriverOptions::default(), &nplc1()).await;
    let v = dmm.acquire(50, Strategy::Stream).await.unwrap().volts();
    for w in v.windows(2) {
        assert!((w[1] - w[0] - 0.0415).abs() < 1e-6, "{w:?}");
    }
    sim.stop().await;
}

async fn recovers_from(fault: Fault, strategy: Strategy) {
    let (mut dmm, sim) = bench(&nplc1()).await;
    sim.inject(fault.clone());
    let acq = dmm.acquire(40, strategy).await.unwrap();
    assert_eq!(acq.readings.len(), 40, "{fault:?} {strategy:?}");
    assert_eq!(acq.retries, 1, "{fault:?} {strategy:?}");
    assert_eq!(sim.stats().device_clears, 2, "connect and one recovery");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn recovery_from_no_reply() {
    for s in [Strategy::Stream, Strategy::Memory, Strategy::Poll] {
        recovers_from(Fault::NoReply, s).await;
    }
}

#[tokio::test(start_paused = true)]
async fn recovery_from_garbled_reply() {
    for s in [Strategy::Stream, Strategy::Memory, Strategy::Poll] {
        recovers_from(Fault::Garble, s).await;
    }
}

#[tokio::test(start_paused = true)]
async fn recovery_from_truncated_reply() {
    for s in [Strategy::Stream, Strategy::Memory, Strategy::Poll] {
        recovers_from(Fault::Truncate, s).await;
    }
}

#[tokio::test(start_paused = true)]
async fn gives_up_after_the_configured_retries() {
    let (link, sim) = sim_dmm(DmmConfig::default(), Box::new(Constant(1.0)), 1);
    let options = DriverOptions {
        retries: 2,
        ..DriverOptions::default()
    };
    let mut dmm = ready(link, options, &nplc1()).await;
    // the first reply of each attempt is lost; the recovery's SYST:ERR? replies come through
    for _ in 0..3 {
        sim.inject(Fault::Garble);
    }
    let err = dmm.acquire(10, Strategy::Poll).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Garbled, "{err}");
    assert!(!err.is_retryable());
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn overloads_are_reported_not_averaged() {
    let (mut dmm, sim) = bench(&nplc1()).await;
    sim.inject(Fault::Overload { readings: 3 });
    let acq = dmm.acquire(10, Strategy::Stream).await.unwrap();
    assert_eq!(acq.overloads(), 3);
    assert_eq!(acq.volts().len(), 7);
    assert!(acq.readings[..3].iter().all(|r| r.is_overload()));
    // beyond the range the meter overloads on its own
    let (mut dmm2, sim2) = bench_with(
        DmmConfig::default(),
        &DcvConfig {
            range: Some(1.0),
            ..nplc1()
        },
        5.0,
    )
    .await;
    let acq = dmm2.acquire(5, Strategy::Memory).await.unwrap();
    assert_eq!(acq.overloads(), 5);
    sim.stop().await;
    sim2.stop().await;
}

#[tokio::test(start_paused = true)]
async fn pushed_error_fails_configure_with_its_text() {
    let (mut dmm, sim) = bench(&nplc1()).await;
    sim.inject(Fault::PushError {
        code: -222,
        message: "Data out of range".into(),
    });
    let err = dmm.configure(&nplc1()).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Instrument);
    assert!(
        err.to_string().contains("-222,\"Data out of range\""),
        "{err}"
    );
    // the queue was drained: the next configure is clean
    dmm.configure(&nplc1()).await.unwrap();
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn dropped_connection_is_a_disconnect() {
    let (mut dmm, sim) = bench(&nplc1()).await;
    sim.inject(Fault::Disconnect);
    let err = dmm.acquire(10, Strategy::Stream).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Disconnected, "{err}");
    assert!(!err.is_retryable());
    assert!(sim.stats().stopped);
}

#[tokio::test(start_paused = true)]
async fn scheduled_fault_from_config() {
    use gyrocal_sim::dmm::ScheduledFault;
    // connect = 6 commands, configure = 9: the first acquisition's READ? reply is lost
    let cfg = DmmConfig {
        faults: vec![ScheduledFault {
            after_commands: 16,
            fault: Fault::NoReply,
        }],
        ..DmmConfig::default()
    };
    let (mut dmm, sim) = bench_with(cfg, &nplc1(), VOLTS).await;
    let acq = dmm.acquire(5, Strategy::Stream).await.unwrap();
    assert_eq!(acq.retries, 1);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn close_returns_to_local() {
    let (dmm, sim) = bench(&nplc1()).await;
    let _link = dmm.close().await.unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert!(!sim.stats().remote);
    sim.stop().await;
}

/// A meter on a slow ramp (0.1 V per second since the bench started, no noise), so each
/// reading tells when it was integrated.
async fn ramp_bench(cfg: DmmConfig) -> (Dmm, DmmHandle, Instant) {
    let origin = Instant::now();
    let cfg = DmmConfig {
        noise_v: 0.0,
        ..cfg
    };
    let (link, sim) = sim_dmm(cfg, Box::new(FnOfTime::new(|t| 0.1 * t)), 1);
    let dmm = ready(link, DriverOptions::default(), &nplc1()).await;
    (dmm, sim, origin)
}

/// Sim seconds since the bench started at which each reading was integrated (mid-window).
fn reading_times(acq: &gyrocal_hp34401a::Acquisition) -> Vec<f64> {
    acq.volts().iter().map(|v| v * 10.0).collect()
}

async fn power_cycle_mid_stream(local_mode: LocalMode, off_s: f64, cause: LinkLoss) {
    let (mut dmm, sim, origin) = ramp_bench(DmmConfig {
        local_mode,
        ..DmmConfig::default()
    })
    .await;
    let before = sim.readings_taken();
    sim.inject_at_reading(before + 250, Fault::PowerCycle { off_s: Some(off_s) });
    let t0 = origin.elapsed().as_secs_f64();
    let acq = dmm.acquire(500, Strategy::Stream).await.unwrap();
    assert_eq!(acq.readings.len(), 500);
    assert_eq!(acq.overloads(), 0);
    assert_eq!(acq.retries, 1);
    assert_eq!(acq.reestablished(), 1, "{:?}", acq.recoveries);
    assert_eq!(acq.recoveries[0].cause, Some(cause));
    let st = sim.stats();
    assert_eq!(st.power_cycles, 1);
    assert!(st.remote);
    // the plan's configuration is back, not the power-on one (NPLC 10)
    assert_eq!(st.nplc, 1.0);
    assert!(st.error_queue.is_empty(), "{:?}", st.error_queue);
    // 249 readings lost with the power cycle, then the 500 again
    assert_eq!(st.readings_taken - before, 249 + 500);
    let times = reading_times(&acq);
    // every reading after the meter came back (reading 250 would have been at about
    // t0 + 0.02 + 250 * 0.0415 s; the meter was off for off_s from there)
    let back = t0 + 0.02 + 249.0 * 0.0415 + off_s;
    assert!(
        times[0] > back,
        "first reading at {} s, meter back at {back} s",
        times[0]
    );
    // and every one at NPLC 1 with autozero (41.5 ms apart), not at the power-on NPLC 10
    for w in times.windows(2) {
        assert!((w[1] - w[0] - 0.0415).abs() < 1e-5, "{w:?}");
    }
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn power_cycle_mid_stream_is_reestablished_and_the_500_readings_taken_again() {
    power_cycle_mid_stream(LocalMode::Refuse, 5.0, LinkLoss::NoAnswer).await;
}

#[tokio::test(start_paused = true)]
async fn power_cycle_of_a_meter_that_answers_in_local_is_seen_by_its_power_on_bit() {
    // the sim's meter obeys in LOCAL and is back (after 0.5 s) before the stream times out:
    // SYST:ERR? is answered after the device clear, and the Power On bit of *ESR? tells the
    // power cycle
    power_cycle_mid_stream(LocalMode::Obey, 0.5, LinkLoss::PowerOn).await;
}

#[tokio::test(start_paused = true)]
async fn power_cycle_in_poll_mode_takes_the_lost_reading_again() {
    let (mut dmm, sim, _) = ramp_bench(DmmConfig::default()).await;
    let before = sim.readings_taken();
    sim.inject_at_reading(before + 20, Fault::PowerCycle { off_s: Some(2.0) });
    let acq = dmm.acquire(40, Strategy::Poll).await.unwrap();
    assert_eq!(acq.readings.len(), 40);
    assert_eq!(acq.reestablished(), 1);
    assert_eq!(sim.stats().nplc, 1.0);
    assert_eq!(sim.readings_taken() - before, 40);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn power_cycle_during_a_memory_burst_is_measured_again_inside_acquire() {
    let (mut dmm, sim, _) = ramp_bench(DmmConfig::default()).await;
    let before = sim.readings_taken();
    // in the second burst of 512
    sim.inject_at_reading(before + 600, Fault::PowerCycle { off_s: None });
    let acq = dmm.acquire(700, Strategy::Memory).await.unwrap();
    assert_eq!(acq.readings.len(), 700);
    assert_eq!(acq.reestablished(), 1);
    let times = reading_times(&acq);
    // the first burst is kept; the second (188 readings) measured again after the cycle
    assert!(
        times[512] - times[511] > 5.0,
        "{} {}",
        times[511],
        times[512]
    );
    for w in times[512..].windows(2) {
        assert!((w[1] - w[0] - 0.0415).abs() < 1e-5, "{w:?}");
    }
    assert_eq!(sim.readings_taken() - before, 512 + 87 + 188);
    assert_eq!(sim.stats().nplc, 1.0);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn fetch_of_a_burst_lost_to_a_power_cycle_is_a_distinct_error() {
    let (mut dmm, sim, _) = ramp_bench(DmmConfig::default()).await;
    let b = dmm.arm_burst(100).await.unwrap();
    dmm.wait_burst(&b).await.unwrap();
    // the meter is switched off and on while the table moves
    sim.inject(Fault::PowerCycle { off_s: Some(2.0) });
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(sim.stats().memory_points, 0);
    // the meter is in LOCAL: FETC? is not answered
    let err = dmm.fetch(&b).await.unwrap_err();
    assert!(err.is_retryable(), "{err}");
    // the caller recovers as after any timeout, and learns the link was re-established
    let r = dmm.recover().await.unwrap();
    assert!(r.reestablished);
    assert_eq!(r.cause, Some(LinkLoss::NoAnswer));
    assert_eq!(sim.stats().nplc, 1.0);
    // fetching again fails at once, clearly, instead of returning other data
    let lines = sim.stats().lines_seen;
    let err = dmm.fetch(&b).await.unwrap_err();
    assert!(
        matches!(err, Error::ReadingsLost { count: 100, .. }),
        "{err}"
    );
    assert_eq!(err.kind(), ErrorKind::ReadingsLost);
    assert!(!err.is_retryable());
    assert!(
        err.to_string().contains("the burst must be measured again"),
        "{err}"
    );
    assert_eq!(sim.stats().lines_seen, lines, "nothing sent");
    // a new burst works
    let b = dmm.arm_burst(10).await.unwrap();
    dmm.wait_burst(&b).await.unwrap();
    assert_eq!(dmm.fetch(&b).await.unwrap().len(), 10);
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn a_meter_that_stays_off_is_given_up_after_reconnect_timeout() {
    let (mut dmm, sim, _) = ramp_bench(DmmConfig::default()).await;
    sim.inject(Fault::PowerCycle {
        off_s: Some(100_000.0),
    });
    tokio::time::sleep(Duration::from_millis(10)).await;
    let t0 = Instant::now();
    let err = dmm.recover().await.unwrap_err();
    let waited = t0.elapsed();
    assert_eq!(err.kind(), ErrorKind::Unreachable, "{err}");
    assert!(!err.is_retryable());
    assert!(
        waited >= Duration::from_secs(30) && waited < Duration::from_millis(30_200),
        "{waited:?}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains(
            "sim-dmm: the multimeter did not come back within 30 s: is it powered and connected?"
        ),
        "{msg}"
    );
    // through acquire: the stream's timeout, the wait for a late reply (3 s), then the same
    // 30 s, and no retry on top
    let t0 = Instant::now();
    let err = dmm.acquire(10, Strategy::Stream).await.unwrap_err();
    assert!(matches!(err, Error::NotBack { .. }), "{err}");
    let waited = t0.elapsed().as_secs_f64();
    let read_timeout = Timing::new(&nplc1()).command_time("READ?").as_secs_f64();
    assert!((34.0..36.0 + read_timeout).contains(&waited), "{waited}");
    sim.stop().await;
}

#[tokio::test(start_paused = true)]
async fn reconnect_timeout_is_an_option() {
    let (link, sim) = sim_dmm(DmmConfig::default(), Box::new(Constant(1.0)), 1);
    let options = DriverOptions {
        reconnect_timeout: Duration::from_secs(8),
        ..DriverOptions::default()
    };
    let mut dmm = ready(link, options, &nplc1()).await;
    sim.inject(Fault::PowerCycle { off_s: Some(60.0) });
    let t0 = Instant::now();
    let err = dmm.recover().await.unwrap_err();
    assert!(err.to_string().contains("within 8 s"), "{err}");
    let waited = t0.elapsed();
    assert!(
        waited >= Duration::from_secs(8) && waited < Duration::from_millis(8_200),
        "{waited:?}"
    );
    sim.stop().await;
}
