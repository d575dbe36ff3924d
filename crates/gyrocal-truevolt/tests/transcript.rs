//! Transcript tests: the exact bytes the Truevolt driver writes, against canned replies.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::time::Duration;

use gyrocal_link::{Field, LinkError, ScriptedTransport, Transport};
use gyrocal_meter::{DcVolts, ErrorKind, Measured, MeterError, Multimeter, Reading};
use gyrocal_truevolt::{Acquisition, Model, TruevoltMeter, TruevoltOptions};

const IDN_61: &str = "Keysight Technologies,34461A,MY53212345,A.02.17-02.40-02.17-00.52-03-01";
const IDN_65: &str = "Keysight Technologies,34465A,MY57600001,A.03.01-03.15-03.01-00.52-03-02";
const IDN_01: &str = "HEWLETT-PACKARD,34401A,0,11-5-2";
const NO_ERROR: &str = "+0,\"No error\"";

mod common;
use common::slow_meter::dcv;

/// A scripted link that behaves as a raw socket: device clear is a reconnect (logged as
/// `(reconnect)` in the transcript, no byte written), no remote command.
struct Lan(ScriptedTransport, Vec<&'static str>);

impl Transport for Lan {
    fn describe(&self) -> &str {
        self.0.describe()
    }
    async fn write_raw(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.0.write_raw(bytes).await
    }
    async fn read_line(&mut self, timeout: Option<Duration>) -> Result<String, LinkError> {
        self.0.read_line(timeout).await
    }
    async fn discard_input(&mut self) -> Result<usize, LinkError> {
        self.0.discard_input().await
    }
    async fn read_field(&mut self, sep: u8, timeout: Option<Duration>) -> Result<Field, LinkError> {
        self.0.read_field(sep, timeout).await
    }
    async fn device_clear(&mut self) -> Result<(), LinkError> {
        self.1.push("reconnect");
        self.0.discard_input().await.map(|_| ())
    }
    fn needs_remote_command(&self) -> bool {
        false
    }
}

fn readings(k: usize, v: f64) -> String {
    vec![
        format!("{v:+.8E}")
            .replace("E", "E+0")
            .replace("E+0-", "E-0");
        k
    ]
    .join(",")
}

fn options(model: Model) -> TruevoltOptions {
    TruevoltOptions::new(model)
}

fn connect_script(idn: &str) -> ScriptedTransport {
    ScriptedTransport::new("tcp://lab-dmm:5025")
        .query("*IDN?", idn)
        .expect_line("*RST;*CLS")
        .query("SYST:ERR?", NO_ERROR)
}

fn configure_script(t: ScriptedTransport) -> ScriptedTransport {
    t.expect_line("CONF:VOLT:DC 10")
        .expect_line("VOLT:DC:NPLC 1")
        .expect_line("VOLT:DC:ZERO:AUTO ON")
        .expect_line("TRIG:SOUR IMM")
        .expect_line("TRIG:DEL:AUTO ON")
        .query("SYST:ERR?", NO_ERROR)
}

async fn ready(t: ScriptedTransport, o: TruevoltOptions) -> TruevoltMeter<Lan> {
    let mut m = TruevoltMeter::new(Lan(t, Vec::new()), o);
    m.connect().await.unwrap();
    m.configure(&dcv()).await.unwrap();
    m
}

#[test]
fn reading_format_helper() {
    assert_eq!(readings(2, 1.0), "+1.00000000E+00,+1.00000000E+00");
    assert_eq!(readings(1, -0.5), "-5.00000000E-01");
}

#[tokio::test(start_paused = true)]
async fn connect_identifies_the_plans_model_and_configures() {
    let t = configure_script(connect_script(IDN_61));
    let m = ready(t, options(Model::M34461A)).await;
    let id = m.identity().unwrap();
    assert_eq!(id.model, "34461A");
    assert_eq!(id.serial, "MY53212345");
    let Lan(mut t, events) = m.into_inner();
    assert_eq!(events, ["reconnect"], "connect starts with a device clear");
    t.done();
}

#[tokio::test(start_paused = true)]
async fn a_truevolt_posing_as_a_34401a_is_accepted_as_the_plans_model() {
    let t = ScriptedTransport::new("tcp://lab-dmm:5025")
        .query("*IDN?", IDN_01)
        .query("SYST:IDEN?", "HP34401A")
        .expect_line("*RST;*CLS")
        .query("SYST:ERR?", NO_ERROR);
    let mut m = TruevoltMeter::new(Lan(t, Vec::new()), options(Model::M34461A));
    let id = m.connect().await.unwrap();
    assert!(id.model.starts_with("34461A"), "{}", id.model);
    assert!(id.model.contains("posing as 34401A"), "{}", id.model);
    assert_eq!(id.raw, IDN_01);
    m.into_inner().0.done();
}

#[tokio::test(start_paused = true)]
async fn a_real_34401a_is_refused() {
    let t = ScriptedTransport::new("tcp://lab-dmm:5025")
        .query("*IDN?", IDN_01)
        .expect_line("SYST:IDEN?")
        .silence()
        .query("SYST:ERR?", "-113,\"Undefined header\"")
        .query("SYST:ERR?", NO_ERROR);
    let mut m = TruevoltMeter::new(Lan(t, Vec::new()), options(Model::M34461A));
    let e = m.connect().await.unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("the plan names a 34461A but a 34401A answered"),
        "{msg}"
    );
    assert!(msg.contains("-113"), "{msg}");
    assert!(msg.starts_with("tcp://lab-dmm:5025"), "{msg}");
    assert_eq!(e.kind(), ErrorKind::Other);
    m.into_inner().0.done();
}

#[tokio::test(start_paused = true)]
async fn another_truevolt_model_is_refused() {
    let t = ScriptedTransport::new("tcp://lab-dmm:5025").query("*IDN?", IDN_65);
    let mut m = TruevoltMeter::new(Lan(t, Vec::new()), options(Model::M34461A));
    let msg = m.connect().await.unwrap_err().to_string();
    assert!(
        msg.contains("the plan names a 34461A but a 34465A answered"),
        "{msg}"
    );
    m.into_inner().0.done();
}

#[tokio::test(start_paused = true)]
async fn a_nplc_the_model_lacks_is_refused_before_sending() {
    let t = connect_script(IDN_61);
    let mut m = TruevoltMeter::new(Lan(t, Vec::new()), options(Model::M34461A));
    m.connect().await.unwrap();
    let e = m
        .configure(&DcVolts {
            nplc: 0.06,
            ..dcv()
        })
        .await
        .unwrap_err();
    assert!(e.to_string().contains("34461A"), "{e}");
    assert!(e.to_string().contains("0.02, 0.2, 1, 10, 100"), "{e}");
    m.into_inner().0.done();
}

#[tokio::test(start_paused = true)]
async fn an_instrument_error_surfaces_with_its_text() {
    let t = connect_script(IDN_61)
        .expect_line("CONF:VOLT:DC 10")
        .expect_line("VOLT:DC:NPLC 1")
        .expect_line("VOLT:DC:ZERO:AUTO ON")
        .expect_line("TRIG:SOUR IMM")
        .expect_line("TRIG:DEL:AUTO ON")
        .query("SYST:ERR?", "-222,\"Data out of range\"")
        .query("SYST:ERR?", NO_ERROR);
    let mut m = TruevoltMeter::new(Lan(t, Vec::new()), options(Model::M34461A));
    m.connect().await.unwrap();
    let e = m.configure(&dcv()).await.unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Instrument);
    assert_eq!(
        e.to_string(),
        "tcp://lab-dmm:5025: the meter reported -222,\"Data out of range\" after configuring DC volts"
    );
    assert!(m.timing().is_none(), "not configured after a refusal");
    m.into_inner().0.done();
}

/// 10,000 readings on a 34461A (memory 10,000): one INIT, drained in chunks of 0.5 s of
/// readings (12 at 41.5 ms) while it measures, the end halved down to a last chunk of 4.
#[tokio::test(start_paused = true)]
async fn stream_of_10000_readings_on_a_34461a() {
    let mut t = configure_script(connect_script(IDN_61))
        .expect_line("SAMP:COUN 10000")
        .expect_line("INIT");
    for _ in 0..832 {
        t = t.query("DATA:REM? 12,WAIT", &readings(12, 1.25));
    }
    t = t
        .query("DATA:REM? 8,WAIT", &readings(8, 1.25))
        .query("DATA:REM? 4,WAIT", &readings(4, 1.25))
        .query(
            "DATA:REM? 4,WAIT",
            &format!("{},+9.90000000E+37", readings(3, 1.25)),
        );
    let mut m = ready(t, options(Model::M34461A)).await;
    let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let s = seen.clone();
    m.set_progress(Some(Box::new(move |p: gyrocal_meter::Progress| {
        s.lock().unwrap().push((p.done, p.total, p.latest));
    })));
    let Measured::Complete(acq) = m.measure(10_000, true).await.unwrap() else {
        panic!("streaming never defers")
    };
    assert_eq!(acq.readings.len(), 10_000);
    assert_eq!(acq.retries, 0);
    assert_eq!(acq.readings[0], Reading::Volts(1.25));
    assert_eq!(acq.readings[9_999], Reading::Overload { positive: true });
    let seen = seen.lock().unwrap();
    assert_eq!(
        seen.len(),
        10_000,
        "progress with every reading, as each chunk arrives"
    );
    assert_eq!(
        seen.last(),
        Some(&(10_000, 10_000, Reading::Overload { positive: true }))
    );
    assert_eq!(seen[0], (1, 10_000, Reading::Volts(1.25)));
    m.into_inner().0.done();
}

/// The sample count is sent only when it changes.
#[tokio::test(start_paused = true)]
async fn the_sample_count_is_sent_only_when_it_changes() {
    let t = configure_script(connect_script(IDN_61))
        .expect_line("SAMP:COUN 3")
        .expect_line("INIT")
        .query("DATA:REM? 3,WAIT", &readings(3, 0.5))
        .expect_line("INIT")
        .query("DATA:REM? 3,WAIT", &readings(3, 0.5));
    let mut m = ready(t, options(Model::M34461A)).await;
    for _ in 0..2 {
        let Measured::Complete(a) = m.measure(3, false).await.unwrap() else {
            panic!()
        };
        assert_eq!(a.readings.len(), 3);
    }
    m.into_inner().0.done();
}

/// Memory mode on a 34460A (memory 1,000): 1,500 readings are a part of 1,000 (fetched at
/// once) and one of 500, whose FETC? is left pending and collected later.
#[tokio::test(start_paused = true)]
async fn memory_mode_with_a_deferred_fetch() {
    let t = configure_script(connect_script(
        "Keysight Technologies,34460A,MY1,A.02.17-02.40-02.17-00.52-03-01",
    ))
    .expect_line("SAMP:COUN 1000")
    .expect_line("INIT")
    .query("*OPC?", "1")
    .query("FETC?", &readings(1000, 2.0))
    .expect_line("SAMP:COUN 500")
    .expect_line("INIT")
    .query("*OPC?", "1")
    .query("FETC?", &readings(500, 3.0));
    let o = TruevoltOptions {
        acquisition: Acquisition::Memory,
        ..options(Model::M34460A)
    };
    let mut m = ready(t, o).await;
    assert_eq!(m.timing().unwrap().acquisition(), "memory");
    let Measured::Pending(p) = m.measure(1_500, true).await.unwrap() else {
        panic!("the last part is left in the meter")
    };
    let acq = m.collect(p).await.unwrap();
    assert_eq!(acq.readings.len(), 1_500);
    assert_eq!(acq.readings[999], Reading::Volts(2.0));
    assert_eq!(acq.readings[1_000], Reading::Volts(3.0));
    assert_eq!(acq.retries, 0);
    m.into_inner().0.done();
}

/// A garbled chunk: the readings it carried were removed from the meter, so after the
/// recovery (reconnect, ABOR, error queue, *ESR?) the rest of the step is measured again;
/// one retry, one note.
#[tokio::test(start_paused = true)]
async fn a_garbled_chunk_is_recovered_and_counted_once() {
    let t = configure_script(connect_script(IDN_61))
        .expect_line("SAMP:COUN 30")
        .expect_line("INIT")
        .query("DATA:REM? 12,WAIT", &readings(12, 1.0))
        .query(
            "DATA:REM? 9,WAIT",
            &readings(9, 1.0).replacen("+1.0", "+1.#", 1),
        )
        .expect_line("ABOR")
        .query("SYST:ERR?", NO_ERROR)
        .query("*ESR?", "+0")
        .expect_line("SAMP:COUN 18")
        .expect_line("INIT")
        .query("DATA:REM? 9,WAIT", &readings(9, 1.0))
        .query("DATA:REM? 5,WAIT", &readings(5, 1.0))
        .query("DATA:REM? 4,WAIT", &readings(4, 1.0));
    let mut m = ready(t, options(Model::M34461A)).await;
    let Measured::Complete(acq) = m.measure(30, false).await.unwrap() else {
        panic!()
    };
    assert_eq!(acq.readings.len(), 30);
    assert_eq!(acq.retries, 1);
    assert_eq!(acq.notes.len(), 1, "{:?}", acq.notes);
    assert!(acq.notes[0].contains("DATA:REM? 9,WAIT"), "{:?}", acq.notes);
    assert!(acq.notes[0].contains("retry 1"), "{:?}", acq.notes);
    let Lan(mut t, events) = m.into_inner();
    assert_eq!(events, ["reconnect", "reconnect"]);
    t.done();
}

/// A meter that stays silent: the budget of 2 retries is spent, then the error says so.
#[tokio::test(start_paused = true)]
async fn a_silent_meter_gives_up_after_the_retry_budget() {
    let recovery = |t: ScriptedTransport| {
        t.expect_line("ABOR")
            .query("SYST:ERR?", NO_ERROR)
            .query("*ESR?", "+0")
    };
    let mut t = configure_script(connect_script(IDN_61))
        .expect_line("SAMP:COUN 3")
        .expect_line("INIT")
        .expect_line("DATA:REM? 3,WAIT")
        .silence()
        // no late reply within max_reply_delay either
        .silence();
    t = recovery(t)
        .expect_line("INIT")
        .expect_line("DATA:REM? 3,WAIT")
        .silence()
        // no late reply within max_reply_delay either
        .silence();
    t = recovery(t)
        .expect_line("INIT")
        .expect_line("DATA:REM? 3,WAIT")
        .silence()
        // no late reply within max_reply_delay either
        .silence();
    let mut m = ready(t, options(Model::M34461A)).await;
    let e = m.measure(3, false).await.unwrap_err();
    assert!(e.to_string().contains("gave up after 3 attempts"), "{e}");
    assert!(e.to_string().contains("DATA:REM? 3,WAIT"), "{e}");
    assert_eq!(e.kind(), ErrorKind::Other);
    m.into_inner().0.done();
}
