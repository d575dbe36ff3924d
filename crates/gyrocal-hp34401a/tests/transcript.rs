//! Transcript tests: the exact bytes the driver writes, against canned replies.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use gyrocal_hp34401a::{
    DcvConfig, DriverOptions, Error, ErrorKind, Hp34401a, LinkLoss, Reading, Strategy,
};
use gyrocal_link::ScriptedTransport;

mod common;
use common::{IDN, NO_ERROR, nplc1};

fn connect_script() -> ScriptedTransport {
    ScriptedTransport::new("dmm")
        .expect_raw(&[0x03])
        .expect_line("SYST:REM")
        .query("*IDN?", IDN)
        .expect_line("*RST;*CLS")
        .query("SYST:ERR?", NO_ERROR)
}

fn configure_script(t: ScriptedTransport) -> ScriptedTransport {
    t.expect_line("CONF:VOLT:DC 10")
        .expect_line("VOLT:DC:NPLC 1")
        .expect_line("ZERO:AUTO ON")
        .expect_line("INP:IMP:AUTO OFF")
        .expect_line("TRIG:SOUR IMM")
        // 75 characters unacknowledged: the driver syncs before going past its budget of 80
        .query("*OPC?", "1")
        .expect_line("TRIG:DEL:AUTO ON")
        .expect_line("TRIG:COUN 1")
        .query("SYST:ERR?", NO_ERROR)
}

async fn ready(t: ScriptedTransport) -> Hp34401a<ScriptedTransport> {
    common::ready(t, DriverOptions::default(), &nplc1()).await
}

#[tokio::test(start_paused = true)]
async fn connect_configure_close() {
    let t = configure_script(connect_script()).expect_line("SYST:LOC");
    let dmm = ready(t).await;
    let id = dmm.identity().unwrap();
    assert_eq!(
        (id.model.as_str(), id.firmware.as_str()),
        ("34401A", "11-5-2")
    );
    let mut t = dmm.close().await.unwrap();
    t.done();
}

#[tokio::test(start_paused = true)]
async fn rwl_when_asked() {
    let t = ScriptedTransport::new("dmm")
        .expect_raw(&[0x03])
        .expect_line("SYST:RWL")
        .query("*IDN?", IDN)
        .expect_line("*RST;*CLS")
        .query("SYST:ERR?", NO_ERROR);
    let opts = DriverOptions {
        lock_front_panel: true,
        ..DriverOptions::default()
    };
    Hp34401a::new(t, opts).connect().await.unwrap();
}

#[tokio::test(start_paused = true)]
async fn another_device_is_refused_by_name() {
    let t = ScriptedTransport::new("dmm")
        .expect_raw(&[0x03])
        .expect_line("SYST:REM")
        .query("*IDN?", "FLUKE,8846A,123,1.0");
    let mut dmm = Hp34401a::new(t, DriverOptions::default());
    let err = dmm.connect().await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Identity);
    assert!(err.to_string().contains("FLUKE,8846A"), "{err}");
}

#[tokio::test(start_paused = true)]
async fn bad_nplc_is_refused_before_anything_is_sent() {
    let mut dmm = Hp34401a::new(connect_script(), DriverOptions::default());
    dmm.connect().await.unwrap();
    let err = dmm
        .configure(&DcvConfig {
            nplc: 2.0,
            ..DcvConfig::default()
        })
        .await
        .unwrap_err();
    assert!(matches!(err, Error::Config(_)), "{err}");
    assert!(err.to_string().contains("NPLC 2"), "{err}");
}

#[tokio::test(start_paused = true)]
async fn meter_errors_after_configure_are_reported_with_their_text() {
    let t = connect_script()
        .expect_line("CONF:VOLT:DC DEF")
        .expect_line("VOLT:DC:RANG:AUTO ON")
        .expect_line("VOLT:DC:NPLC 10")
        .expect_line("ZERO:AUTO ON")
        .query("*OPC?", "1")
        .expect_line("INP:IMP:AUTO OFF")
        .expect_line("TRIG:SOUR IMM")
        .expect_line("TRIG:DEL:AUTO ON")
        .expect_line("TRIG:COUN 1")
        .query("SYST:ERR?", "-222,\"Data out of range\"")
        .query("SYST:ERR?", NO_ERROR);
    let mut dmm = Hp34401a::new(t, DriverOptions::default());
    dmm.connect().await.unwrap();
    let err = dmm.configure(&DcvConfig::default()).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Instrument);
    assert!(
        err.to_string().contains("-222,\"Data out of range\""),
        "{err}"
    );
}

#[tokio::test(start_paused = true)]
async fn stream_bytes() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 3")
        .query("READ?", "+1.00000000E+00,+9.90000000E+37,-2.50000000E-03");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(3, Strategy::Stream).await.unwrap();
    assert_eq!(
        acq.readings,
        [
            Reading::Volts(1.0),
            Reading::Overload { positive: true },
            Reading::Volts(-2.5e-3)
        ]
    );
    assert_eq!(acq.overloads(), 1);
    assert_eq!(acq.volts(), [1.0, -2.5e-3]);
}

#[tokio::test(start_paused = true)]
async fn memory_bytes_in_bursts_of_512() {
    let burst = vec!["+1.00000000E+00"; 512].join(",");
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 512")
        .query("INIT;*OPC?", "1")
        .query("FETC?", &burst)
        .expect_line("SAMP:COUN 2")
        .query("INIT;*OPC?", "1")
        .query("FETC?", "+2.00000000E+00,+3.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(514, Strategy::Memory).await.unwrap();
    assert_eq!(acq.readings.len(), 514);
    assert_eq!(acq.readings[513], Reading::Volts(3.0));
}

#[tokio::test(start_paused = true)]
async fn split_burst_steps() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 2")
        .query("INIT;*OPC?", "1")
        .query("FETC?", "+2.00000000E+00,+3.00000000E+00");
    let mut dmm = ready(t).await;
    let b = dmm.arm_burst(2).await.unwrap();
    dmm.wait_burst(&b).await.unwrap();
    assert_eq!(
        dmm.fetch(&b).await.unwrap(),
        [Reading::Volts(2.0), Reading::Volts(3.0)]
    );
    assert!(dmm.arm_burst(513).await.is_err());
}

#[tokio::test(start_paused = true)]
async fn poll_bytes() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 1")
        .query("READ?", "+1.00000000E+00")
        .query("READ?", "+2.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(2, Strategy::Poll).await.unwrap();
    assert_eq!(acq.volts(), [1.0, 2.0]);
}

#[tokio::test(start_paused = true)]
async fn auto_streams_at_nplc_1() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 1")
        .query("READ?", "+1.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(1, Strategy::Auto).await.unwrap();
    assert_eq!(acq.strategy, Strategy::Stream);
}

#[tokio::test(start_paused = true)]
async fn timeout_then_device_clear_drain_and_retry() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 2")
        .expect_line("READ?")
        .silence()
        // no late reply within max_reply_delay either
        .silence()
        .expect_raw(&[0x03])
        .query("SYST:ERR?", "-410,\"Query INTERRUPTED\"")
        .query("SYST:ERR?", NO_ERROR)
        // the Power On bit is clear: the meter kept its configuration, a plain retry
        .query("*ESR?", "+4")
        .expect_line("SAMP:COUN 2")
        .query("READ?", "+1.00000000E+00,+2.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(2, Strategy::Stream).await.unwrap();
    assert_eq!(acq.retries, 1);
    assert_eq!(acq.volts(), [1.0, 2.0]);
    assert_eq!(acq.reestablished(), 0);
    assert_eq!(acq.recoveries[0].errors[0].code, -410);
    assert_eq!(dmm.link_epoch(), 0);
}

/// A reply that comes after its deadline is recognised as the late answer to the query that
/// timed out (only one is ever outstanding) and thrown away: it is never read as the answer
/// to `SYST:ERR?`, and the retry's readings are the retry's. The deadlines widen, and the
/// device clear now drains until the link is quiet.
#[tokio::test(start_paused = true)]
async fn a_late_reply_is_thrown_away_and_never_taken_for_the_next_answer() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 1")
        .expect_line("READ?")
        .silence()
        // the late reply to READ?
        .reply("+1.00000000E+00")
        .expect_raw(&[0x03])
        // drained until quiet: nothing more on its way
        .silence()
        .query("SYST:ERR?", NO_ERROR)
        .query("*ESR?", "+0")
        .expect_line("SAMP:COUN 1")
        .query("READ?", "+3.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(1, Strategy::Stream).await.unwrap();
    assert_eq!(acq.volts(), [3.0]);
    assert_eq!(acq.retries, 1);
    assert_eq!(acq.reestablished(), 0);
    let note = acq.recoveries[0].describe();
    assert!(
        note.starts_with("the meter answers slowly: the reply came")
            && note.ends_with("device clear"),
        "{note}"
    );
    assert!(dmm.reply_delay() > std::time::Duration::ZERO);
}

#[tokio::test(start_paused = true)]
async fn garbled_reading_names_the_bytes_and_gives_up() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 2")
        .query("READ?", "+1.00000000E+00,+2.0#000000E+00")
        .expect_raw(&[0x03])
        .query("SYST:ERR?", NO_ERROR)
        .query("*ESR?", "+0")
        .expect_line("SAMP:COUN 2")
        .query("READ?", "+1.00000000E+00,HELLO");
    let mut dmm = Hp34401a::new(
        t,
        DriverOptions {
            retries: 1,
            ..DriverOptions::default()
        },
    );
    dmm.connect().await.unwrap();
    dmm.configure(&nplc1()).await.unwrap();
    let err = dmm.acquire(2, Strategy::Stream).await.unwrap_err();
    assert!(matches!(err, Error::GaveUp { attempts: 2, .. }), "{err}");
    assert_eq!(err.kind(), ErrorKind::Garbled);
    assert!(!err.is_retryable());
    assert!(err.to_string().contains("HELLO"), "{err}");
}

#[tokio::test(start_paused = true)]
async fn wrong_count_is_garbled() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 3")
        .query("READ?", "+1.00000000E+00,+2.00000000E+00");
    let mut dmm = Hp34401a::new(
        t,
        DriverOptions {
            retries: 0,
            ..DriverOptions::default()
        },
    );
    dmm.connect().await.unwrap();
    dmm.configure(&nplc1()).await.unwrap();
    let err = dmm.acquire(3, Strategy::Stream).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Garbled);
}

#[tokio::test(start_paused = true)]
async fn disconnect_is_not_retried() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 1")
        .expect_line("READ?")
        .disconnect();
    let mut dmm = ready(t).await;
    let err = dmm.acquire(1, Strategy::Stream).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Disconnected);
    assert!(!err.is_retryable());
}

#[tokio::test(start_paused = true)]
async fn acquire_needs_configure() {
    let mut dmm = Hp34401a::new(connect_script(), DriverOptions::default());
    dmm.connect().await.unwrap();
    let err = dmm.acquire(1, Strategy::Stream).await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Config);
}

/// The re-establish sequence after the link was found lost: device clear, `SYST:REM`, `*CLS`,
/// `*IDN?`, the configuration of `configure` again, the error queue drained.
fn reestablish_script(t: ScriptedTransport) -> ScriptedTransport {
    configure_script(
        t.expect_raw(&[0x03])
            .expect_line("SYST:REM")
            .expect_line("*CLS")
            .query("*IDN?", IDN),
    )
}

#[tokio::test(start_paused = true)]
async fn no_answer_after_device_clear_reestablishes_the_link_and_streams_again() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 2")
        .expect_line("READ?")
        .silence()
        // no late reply within max_reply_delay either
        .silence()
        .expect_raw(&[0x03])
        .expect_line("SYST:ERR?")
        .silence();
    let t = reestablish_script(t)
        .expect_line("SAMP:COUN 2")
        .query("READ?", "+1.00000000E+00,+2.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(2, Strategy::Stream).await.unwrap();
    assert_eq!(acq.volts(), [1.0, 2.0]);
    assert_eq!(acq.retries, 1);
    assert_eq!(acq.reestablished(), 1);
    let r = &acq.recoveries[0];
    assert!(r.reestablished);
    assert_eq!(r.cause, Some(LinkLoss::NoAnswer));
    assert_eq!(r.attempts, 1);
    assert!(r.describe().contains("re-established"), "{}", r.describe());
    assert_eq!(dmm.link_epoch(), 1);
    assert_eq!(dmm.config(), Some(&nplc1()));
}

#[tokio::test(start_paused = true)]
async fn power_on_bit_reestablishes_the_link() {
    // a meter that answers in LOCAL (unpredictable per the manual) still shows its Power On bit
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 1")
        .expect_line("READ?")
        .silence()
        // no late reply within max_reply_delay either
        .silence()
        .expect_raw(&[0x03])
        .query("SYST:ERR?", NO_ERROR)
        .query("*ESR?", "+128");
    let t = reestablish_script(t)
        .expect_line("SAMP:COUN 1")
        .query("READ?", "+1.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(1, Strategy::Stream).await.unwrap();
    assert_eq!(acq.recoveries[0].cause, Some(LinkLoss::PowerOn));
}

#[tokio::test(start_paused = true)]
async fn error_550_reestablishes_the_link_and_reports_the_queue() {
    // someone pressed LOCAL: the meter refused what followed with 550
    let t = configure_script(connect_script())
        .expect_raw(&[0x03])
        .query("SYST:ERR?", "+550,\"Command not allowed in local\"")
        .query("SYST:ERR?", NO_ERROR);
    let t = reestablish_script(t);
    let mut dmm = ready(t).await;
    let r = dmm.recover().await.unwrap();
    assert!(r.reestablished);
    assert_eq!(r.cause, Some(LinkLoss::Local));
    assert_eq!(r.errors[0].code, 550);
}

#[tokio::test(start_paused = true)]
async fn a_meter_still_off_is_tried_again_after_a_pause() {
    let t = configure_script(connect_script())
        .expect_raw(&[0x03])
        .expect_line("SYST:ERR?")
        .silence()
        // first attempt: the meter is still off
        .expect_raw(&[0x03])
        .expect_line("SYST:REM")
        .expect_line("*CLS")
        .expect_line("*IDN?")
        .silence();
    let t = reestablish_script(t);
    let mut dmm = ready(t).await;
    let t0 = tokio::time::Instant::now();
    let r = dmm.recover().await.unwrap();
    assert!(r.reestablished);
    assert_eq!(r.attempts, 2);
    // three device clears (100 ms each) and one pause (1 s); silences cost no virtual time here
    assert_eq!(t0.elapsed(), std::time::Duration::from_millis(1300));
}

#[tokio::test(start_paused = true)]
async fn fetch_of_a_burst_armed_before_a_reestablish_fails_without_sending() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 2")
        .query("INIT;*OPC?", "1")
        .expect_raw(&[0x03])
        .expect_line("SYST:ERR?")
        .silence();
    let t = reestablish_script(t);
    let mut dmm = ready(t).await;
    let b = dmm.arm_burst(2).await.unwrap();
    dmm.wait_burst(&b).await.unwrap();
    assert!(dmm.recover().await.unwrap().reestablished);
    // nothing is sent: the script has no FETC?
    let err = dmm.fetch(&b).await.unwrap_err();
    assert!(matches!(err, Error::ReadingsLost { count: 2, .. }), "{err}");
    assert_eq!(err.kind(), ErrorKind::ReadingsLost);
    assert!(!err.is_retryable());
    assert!(
        err.to_string()
            .contains("memory was cleared since the burst of 2 readings was armed (gyrocal configured the meter again after it did not answer, which clears its memory; no power cycle was seen: its replies may be too late or lost): the burst must be measured again"),
        "{err}"
    );
    assert!(matches!(
        dmm.wait_burst(&b).await,
        Err(Error::ReadingsLost { .. })
    ));
}

#[tokio::test(start_paused = true)]
async fn memory_burst_lost_in_acquire_is_measured_again() {
    let t = configure_script(connect_script())
        .expect_line("SAMP:COUN 2")
        .expect_line("INIT;*OPC?")
        .silence()
        // no late reply within max_reply_delay either
        .silence()
        .expect_raw(&[0x03])
        .expect_line("SYST:ERR?")
        .silence();
    let t = reestablish_script(t)
        .expect_line("SAMP:COUN 2")
        .query("INIT;*OPC?", "1")
        .query("FETC?", "+2.00000000E+00,+3.00000000E+00");
    let mut dmm = ready(t).await;
    let acq = dmm.acquire(2, Strategy::Memory).await.unwrap();
    assert_eq!(acq.volts(), [2.0, 3.0]);
    assert_eq!(acq.reestablished(), 1);
}

#[tokio::test(start_paused = true)]
async fn another_instrument_after_the_reestablish_is_retried_then_named() {
    let opts = DriverOptions {
        reconnect_timeout: std::time::Duration::from_millis(250),
        ..DriverOptions::default()
    };
    let t = configure_script(connect_script())
        .expect_raw(&[0x03])
        .expect_line("SYST:ERR?")
        .silence()
        .expect_raw(&[0x03])
        .expect_line("SYST:REM")
        .expect_line("*CLS")
        .query("*IDN?", "FLUKE,8846A,123,1.0")
        .expect_raw(&[0x03])
        .expect_line("SYST:REM")
        .expect_line("*CLS")
        .query("*IDN?", "FLUKE,8846A,123,1.0");
    let mut dmm = Hp34401a::new(t, opts);
    dmm.connect().await.unwrap();
    dmm.configure(&nplc1()).await.unwrap();
    let err = dmm.recover().await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Unreachable);
    assert!(!err.is_retryable());
    let msg = err.to_string();
    assert!(
        msg.contains("dmm: the multimeter did not come back within"),
        "{msg}"
    );
    assert!(msg.contains("FLUKE,8846A"), "{msg}");
}

/// Over GPIB through a Prologix controller: the controller's set-up, `++clr` as the device
/// clear, no `SYST:REM`, every reply fetched with `++read eoi`, no `SYST:LOC` at close.
#[tokio::test]
async fn connect_and_close_over_a_prologix_controller() {
    use gyrocal_link::{PrologixOptions, PrologixTransport};
    let script = ScriptedTransport::new("prologix")
        .expect_line("++savecfg 0")
        .expect_line("++mode 1")
        .expect_line("++ifc")
        .expect_line("++addr 22")
        .expect_line("++auto 0")
        .expect_line("++eoi 1")
        .expect_line("++eos 2")
        .expect_line("++eot_enable 0")
        .expect_line("++read_tmo_ms 1000")
        .query("++ver", "Prologix GPIB-USB Controller version 6.107")
        .expect_line("++clr")
        .expect_line("*IDN?")
        .query("++read eoi", IDN)
        .expect_line("*RST;*CLS")
        .expect_line("SYST:ERR?")
        .query("++read eoi", NO_ERROR)
        // back to local at the close: the controller's go-to-local, not SYST:LOC
        .expect_line("++loc");
    let link = PrologixTransport::open(script, PrologixOptions::default())
        .await
        .unwrap();
    let mut dmm = Hp34401a::new(
        link,
        DriverOptions {
            clear_settle: std::time::Duration::ZERO,
            ..DriverOptions::default()
        },
    );
    dmm.connect().await.unwrap();
    dmm.close().await.unwrap().into_inner().done();
}

/// A meter whose error queue never empties (a fault that refills it) is asked a bounded number
/// of times: 24 `SYST:ERR?` (the 20-entry queue and a few arriving meanwhile), every entry
/// kept, nothing more sent.
#[tokio::test(start_paused = true)]
async fn an_error_queue_that_never_empties_is_read_a_bounded_number_of_times() {
    let mut t = connect_script();
    for _ in 0..24 {
        t = t.query("SYST:ERR?", "-350,\"Queue overflow\"");
    }
    let mut dmm = Hp34401a::new(t, DriverOptions::default());
    dmm.connect().await.unwrap();
    let errors = dmm.drain_errors().await.unwrap();
    assert_eq!(errors.len(), 24);
    assert_eq!(errors[0].to_string(), "-350,\"Queue overflow\"");
    dmm.into_inner().done();
}

/// A garbled error-queue entry is an error that names the device and the bytes received.
#[tokio::test(start_paused = true)]
async fn a_garbled_error_queue_entry_names_the_bytes() {
    let t = connect_script().query("SYST:ERR?", "+#,\"No error\"");
    let mut dmm = Hp34401a::new(t, DriverOptions::default());
    dmm.connect().await.unwrap();
    let err = dmm.drain_errors().await.unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Garbled);
    let text = err.to_string();
    assert!(
        text.starts_with("dmm: expected an error-queue entry"),
        "{text}"
    );
    assert!(text.contains("+#,"), "{text}");
    dmm.into_inner().done();
}
