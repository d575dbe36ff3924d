//! Transcript tests of the Watlow F4 dialect: the exact Modbus frames on the wire, checked by a
//! scripted peer of this file's own at the other end of an in-memory pipe. The frames are built
//! here from the Modbus specification (function codes, big-endian fields, the CRC-16 with the
//! reflected polynomial 0xA001, sent low byte first), independently of tokio-modbus, and the two
//! frames the brief names are also written out byte by byte.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Duration;

use gyrocal_chamber::{
    Chamber, ChamberErrorKind, ChamberMode, ProductInput, SafeState, WatlowConfig, WatlowF4,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt, DuplexStream};
use tokio::task::JoinHandle;
use tokio::time::Instant;

// --- frames, from the Modbus specification -------------------------------------------------

/// CRC-16/MODBUS: initial 0xFFFF, each byte XORed in low, shifted right, 0xA001 on a carry out.
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

fn rtu(mut frame: Vec<u8>) -> Vec<u8> {
    let c = crc(&frame);
    frame.extend_from_slice(&c);
    frame
}

fn read_request(addr: u16, count: u16) -> Vec<u8> {
    let [ah, al] = addr.to_be_bytes();
    let [ch, cl] = count.to_be_bytes();
    rtu(vec![1, 0x03, ah, al, ch, cl])
}

fn read_reply(words: &[i16]) -> Vec<u8> {
    let mut f = vec![1, 0x03, (2 * words.len()) as u8];
    for w in words {
        f.extend_from_slice(&w.to_be_bytes());
    }
    rtu(f)
}

fn write_request(addr: u16, value: i16) -> Vec<u8> {
    let [ah, al] = addr.to_be_bytes();
    let [vh, vl] = value.to_be_bytes();
    rtu(vec![1, 0x06, ah, al, vh, vl])
}

fn exception_reply(function: u8, code: u8) -> Vec<u8> {
    rtu(vec![1, function | 0x80, code])
}

// --- the scripted peer ---------------------------------------------------------------------

/// One exchange: the exact request expected, then the reply (none: the slave stays silent).
struct Exchange {
    request: Vec<u8>,
    reply: Option<Vec<u8>>,
    /// How long the slave takes before it replies.
    delay: Duration,
}

fn ask(request: Vec<u8>, reply: Vec<u8>) -> Exchange {
    Exchange {
        request,
        reply: Some(reply),
        delay: Duration::ZERO,
    }
}

fn late(request: Vec<u8>, reply: Vec<u8>, delay: Duration) -> Exchange {
    Exchange {
        request,
        reply: Some(reply),
        delay,
    }
}

fn silent(request: Vec<u8>) -> Exchange {
    Exchange {
        request,
        reply: None,
        delay: Duration::ZERO,
    }
}

/// Plays `script` on the device side; at the end (the driver dropped) checks that nothing
/// more was sent. Returns what it saw, for the failure message.
fn peer(mut io: DuplexStream, script: Vec<Exchange>) -> JoinHandle<()> {
    tokio::spawn(async move {
        for (i, ex) in script.into_iter().enumerate() {
            let mut got = vec![0u8; ex.request.len()];
            io.read_exact(&mut got)
                .await
                .unwrap_or_else(|e| panic!("exchange {i}: request not received: {e}"));
            assert_eq!(
                got, ex.request,
                "exchange {i}: request bytes {got:02X?}, expected {:02X?}",
                ex.request
            );
            if let Some(reply) = ex.reply {
                tokio::time::sleep(ex.delay).await;
                io.write_all(&reply).await.unwrap();
            }
        }
        let mut rest = Vec::new();
        io.read_to_end(&mut rest).await.unwrap();
        assert!(rest.is_empty(), "bytes sent after the script: {rest:02X?}");
    })
}

fn chamber(config: WatlowConfig, script: Vec<Exchange>) -> (WatlowF4, JoinHandle<()>) {
    let (host, device) = tokio::io::duplex(4096);
    let f4 = WatlowF4::over_stream(host, "pipe", 9600, config).unwrap();
    (f4, peer(device, script))
}

/// The connect exchanges of a controller in °C, one decimal everywhere, input 1 range
/// −70.0 .. 180.0 °C, product on input 2.
fn connect_script() -> Vec<Exchange> {
    vec![
        ask(read_request(901, 1), read_reply(&[1])),
        ask(read_request(606, 1), read_reply(&[1])),
        ask(read_request(602, 2), read_reply(&[-700, 1800])),
        ask(read_request(616, 1), read_reply(&[1])),
    ]
}

fn script(parts: &[Vec<Exchange>]) -> Vec<Exchange> {
    let mut out = Vec::new();
    for p in parts {
        out.extend(p.iter().map(|e| Exchange {
            request: e.request.clone(),
            reply: e.reply.clone(),
            delay: e.delay,
        }));
    }
    out
}

async fn finish(f4: WatlowF4, peer: JoinHandle<()>) {
    drop(f4);
    peer.await.unwrap();
}

// --- the tests -----------------------------------------------------------------------------

#[test]
fn the_named_frames_are_the_specifications() {
    // Read holding registers 100..=108 at slave 1, and write 300 = 25.0 °C (250) at slave 1.
    assert_eq!(
        read_request(100, 9),
        [0x01, 0x03, 0x00, 0x64, 0x00, 0x09, 0xC4, 0x13]
    );
    assert_eq!(
        write_request(300, 250),
        [0x01, 0x06, 0x01, 0x2C, 0x00, 0xFA, 0xC9, 0xBC]
    );
    // The specification's own CRC example (Modbus over serial line V1.02, appendix B).
    assert_eq!(crc(&[0x02, 0x07]), [0x41, 0x12]);
}

#[tokio::test(start_paused = true)]
async fn connect_then_a_reading_of_negative_temperatures() {
    let reading = vec![
        // 100..=108: air −20.5 (0xFF33), 101..103, product (104) −19.8, 105..108
        ask(
            read_request(100, 9),
            read_reply(&[-205, 0, 0, 4500, -198, 0, 0, 0, 0]),
        ),
        ask(read_request(200, 1), read_reply(&[1])),
        ask(read_request(300, 1), read_reply(&[-200])),
    ];
    let (mut f4, peer) = chamber(
        WatlowConfig::default(),
        script(&[connect_script(), reading]),
    );
    let id = f4.connect().await.unwrap();
    assert_eq!(id.model, "Watlow F4");
    assert!(id.detail.contains("range -70 .. 180 °C"), "{}", id.detail);
    assert_eq!(f4.limits(), (-40.0, 85.0));
    let r = f4.read().await.unwrap();
    assert_eq!(r.air_c, -20.5);
    assert_eq!(r.product_c, Some(-19.8));
    assert_eq!(r.setpoint_c, -20.0);
    assert_eq!(r.mode, ChamberMode::Constant);
    assert!(r.alarms.is_empty());
    assert!(f4.take_retries().is_empty());
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_setpoint_terminates_a_profile_then_is_written_and_read_back() {
    let set = vec![
        ask(read_request(200, 1), read_reply(&[2])), // a profile of the controller's runs
        ask(write_request(1217, 1), write_request(1217, 1)),
        ask(write_request(300, 250), write_request(300, 250)),
        ask(read_request(300, 1), read_reply(&[250])),
    ];
    let (mut f4, peer) = chamber(WatlowConfig::default(), script(&[connect_script(), set]));
    f4.connect().await.unwrap();
    f4.set_setpoint(25.0).await.unwrap();
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_negative_setpoint_is_twos_complement() {
    let set = vec![
        ask(read_request(200, 1), read_reply(&[0])),
        ask(write_request(300, -205), write_request(300, -205)),
        ask(read_request(300, 1), read_reply(&[-205])),
    ];
    // The frame itself, written out: 0xFF33 is −205.
    assert_eq!(
        write_request(300, -205),
        [0x01, 0x06, 0x01, 0x2C, 0xFF, 0x33, 0x48, 0x1A]
    );
    let (mut f4, peer) = chamber(WatlowConfig::default(), script(&[connect_script(), set]));
    f4.connect().await.unwrap();
    f4.set_setpoint(-20.5).await.unwrap();
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_setpoint_read_back_otherwise_is_an_error() {
    let set = vec![
        ask(read_request(200, 1), read_reply(&[0])),
        ask(write_request(300, 600), write_request(300, 600)),
        ask(read_request(300, 1), read_reply(&[250])),
    ];
    let (mut f4, peer) = chamber(WatlowConfig::default(), script(&[connect_script(), set]));
    f4.connect().await.unwrap();
    let e = f4.set_setpoint(60.0).await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Instrument);
    assert!(e.to_string().contains("read back 25 °C"), "{e}");
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_setpoint_outside_the_limits_sends_nothing() {
    let (mut f4, peer) = chamber(
        WatlowConfig {
            max_c: 200.0,
            ..WatlowConfig::default()
        },
        connect_script(),
    );
    f4.connect().await.unwrap();
    // The configuration allows 200 °C; the controller's input range stops at 180.
    assert_eq!(f4.limits(), (-40.0, 180.0));
    let e = f4.set_setpoint(190.0).await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Limit);
    assert!(e.to_string().contains("-40 .. 180"), "{e}");
    let e = f4.set_setpoint(f64::NAN).await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Limit);
    finish(f4, peer).await; // the peer checks nothing more was sent
}

#[tokio::test(start_paused = true)]
async fn an_exception_reply_is_an_instrument_error_naming_it_and_the_register() {
    let (mut f4, peer) = chamber(
        WatlowConfig::default(),
        vec![ask(read_request(901, 1), exception_reply(0x03, 2))],
    );
    let e = f4.connect().await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Instrument);
    let msg = e.to_string();
    assert!(
        msg.contains("Modbus exception 2 (illegal data address)"),
        "{msg}"
    );
    assert!(msg.contains("read register 901"), "{msg}");
    assert!(
        f4.take_retries().is_empty(),
        "an exception is not asked again"
    );
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_crc_corrupted_reply_is_asked_again_and_noted() {
    let mut corrupted = read_reply(&[1]);
    let last = corrupted.len() - 1;
    corrupted[last] ^= 0xFF;
    let mut s = vec![ask(read_request(901, 1), corrupted)];
    s.extend(connect_script());
    let (mut f4, peer) = chamber(WatlowConfig::default(), s);
    f4.connect().await.unwrap();
    let notes = f4.take_retries();
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(notes[0].contains("read register 901"), "{}", notes[0]);
    assert!(notes[0].contains("CRC error"), "{}", notes[0]);
    assert!(notes[0].contains("attempt 2 of 3"), "{}", notes[0]);
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn garbled_every_time_is_a_garbled_error_after_the_retries() {
    let mut corrupted = read_reply(&[1]);
    corrupted[3] ^= 0x01;
    let s = (0..3)
        .map(|_| ask(read_request(901, 1), corrupted.clone()))
        .collect();
    let (mut f4, peer) = chamber(WatlowConfig::default(), s);
    let e = f4.connect().await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Garbled);
    assert!(e.to_string().contains("asked 3 times"), "{e}");
    assert_eq!(f4.take_retries().len(), 2);
    finish(f4, peer).await;
}

/// The setpoint's echo corrupted (a CRC error): register 300 holds a level, so the same
/// write is sent again (noted like a query's retry), then read back.
#[tokio::test(start_paused = true)]
async fn a_setpoint_whose_echo_is_garbled_is_written_again_and_read_back() {
    let mut corrupted = write_request(300, 250);
    corrupted[7] ^= 0x10;
    let set = vec![
        ask(read_request(200, 1), read_reply(&[0])),
        ask(write_request(300, 250), corrupted),
        ask(write_request(300, 250), write_request(300, 250)),
        ask(read_request(300, 1), read_reply(&[250])),
    ];
    let (mut f4, peer) = chamber(WatlowConfig::default(), script(&[connect_script(), set]));
    f4.connect().await.unwrap();
    f4.set_setpoint(25.0).await.unwrap();
    let notes = f4.take_retries();
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(
        notes[0].contains("write register 300 = 250")
            && notes[0].contains("CRC error")
            && notes[0].contains("written again, the same value (attempt 2 of 3)"),
        "{notes:?}"
    );
    finish(f4, peer).await;
}

/// Every echo of the setpoint's write garbled: a garbled error after the retries, the write
/// sent `1 + retries` times and no more.
#[tokio::test(start_paused = true)]
async fn a_setpoint_garbled_every_time_is_a_garbled_error_after_the_retries() {
    let mut corrupted = write_request(300, 250);
    corrupted[7] ^= 0x10;
    let mut set = vec![ask(read_request(200, 1), read_reply(&[0]))];
    set.extend((0..3).map(|_| ask(write_request(300, 250), corrupted.clone())));
    let (mut f4, peer) = chamber(WatlowConfig::default(), script(&[connect_script(), set]));
    f4.connect().await.unwrap();
    let e = f4.set_setpoint(25.0).await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Garbled);
    assert!(e.to_string().contains("asked 3 times"), "{e}");
    finish(f4, peer).await;
}

/// A command whose echo is garbled (1217, terminate the controller's profile: an action) is
/// not sent again.
#[tokio::test(start_paused = true)]
async fn a_command_whose_echo_is_garbled_is_not_sent_again() {
    let mut corrupted = write_request(1217, 1);
    corrupted[7] ^= 0x10;
    let set = vec![
        ask(read_request(200, 1), read_reply(&[2])),
        ask(write_request(1217, 1), corrupted),
    ];
    let (mut f4, peer) = chamber(WatlowConfig::default(), script(&[connect_script(), set]));
    f4.connect().await.unwrap();
    let e = f4.set_setpoint(25.0).await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Garbled);
    assert!(e.to_string().contains("not sent again"), "{e}");
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_silent_slave_times_out_exactly_after_its_retries() {
    let s = (0..3).map(|_| silent(read_request(901, 1))).collect();
    let (mut f4, peer) = chamber(WatlowConfig::default(), s);
    let t0 = Instant::now();
    let e = f4.connect().await.unwrap_err();
    // Three attempts of the 1 s reply timeout each, in virtual time: exact.
    assert_eq!(t0.elapsed(), Duration::from_secs(3));
    assert_eq!(e.kind(), ChamberErrorKind::Timeout);
    assert!(e.to_string().contains("the chamber is silent"), "{e}");
    assert!(e.to_string().contains("within 1000 ms"), "{e}");
    finish(f4, peer).await;
}

/// A slow reply (after the timeout) is not taken for a later request's: the late bytes are
/// thrown away before the next request is sent.
#[tokio::test(start_paused = true)]
async fn a_late_reply_is_never_read_as_another_requests() {
    let s = vec![
        silent(read_request(901, 1)),
        silent(read_request(901, 1)),
        late(
            read_request(901, 1),
            read_reply(&[1]),
            Duration::from_millis(1500),
        ),
        ask(read_request(901, 1), read_reply(&[1])),
        ask(read_request(606, 1), read_reply(&[2])),
        ask(read_request(602, 2), read_reply(&[-7000, 18000])),
        ask(read_request(616, 1), read_reply(&[2])),
    ];
    let (mut f4, peer) = chamber(WatlowConfig::default(), s);
    let e = f4.connect().await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Timeout);
    // The third attempt's reply arrives while the run does something else.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let id = f4.connect().await.unwrap();
    assert!(
        id.detail.contains("input 1 (air) 2 decimals"),
        "{}",
        id.detail
    );
    assert!(id.detail.contains("range -70 .. 180 °C"), "{}", id.detail);
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_controller_in_fahrenheit_is_refused() {
    let (mut f4, peer) = chamber(
        WatlowConfig::default(),
        vec![ask(read_request(901, 1), read_reply(&[0]))],
    );
    let e = f4.connect().await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Setup);
    assert!(e.to_string().contains("°F"), "{e}");
    assert!(e.to_string().contains("set it to °C"), "{e}");
    // Nothing can be set or read on a controller that was refused.
    assert_eq!(
        f4.set_setpoint(25.0).await.unwrap_err().kind(),
        ChamberErrorKind::State
    );
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn decimals_out_of_range_are_refused() {
    let (mut f4, peer) = chamber(
        WatlowConfig::default(),
        vec![
            ask(read_request(901, 1), read_reply(&[1])),
            ask(read_request(606, 1), read_reply(&[7])),
        ],
    );
    let e = f4.connect().await.unwrap_err();
    assert_eq!(e.kind(), ChamberErrorKind::Setup);
    assert!(e.to_string().contains("register 606"), "{e}");
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_refused_block_read_falls_back_to_single_registers() {
    let reading = vec![
        ask(read_request(100, 9), exception_reply(0x03, 2)),
        ask(read_request(100, 1), read_reply(&[231])),
        ask(read_request(104, 1), read_reply(&[229])),
        ask(read_request(200, 1), read_reply(&[0])),
        ask(read_request(300, 1), read_reply(&[230])),
        // The next reading goes straight to single registers.
        ask(read_request(100, 1), read_reply(&[232])),
        ask(read_request(104, 1), read_reply(&[230])),
        ask(read_request(200, 1), read_reply(&[0])),
        ask(read_request(300, 1), read_reply(&[230])),
    ];
    let (mut f4, peer) = chamber(
        WatlowConfig::default(),
        script(&[connect_script(), reading]),
    );
    f4.connect().await.unwrap();
    let r = f4.read().await.unwrap();
    assert_eq!((r.air_c, r.product_c), (23.1, Some(22.9)));
    let r = f4.read().await.unwrap();
    assert_eq!((r.air_c, r.product_c), (23.2, Some(23.0)));
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn configured_alarms_and_input_3() {
    let config = WatlowConfig {
        product_input: ProductInput::Input3,
        alarms: vec![gyrocal_chamber::AlarmRegister {
            register: 1061,
            mask: 0x0001,
            active: 0x0001,
            name: "door open".into(),
        }],
        ..WatlowConfig::default()
    };
    let connect = vec![
        ask(read_request(901, 1), read_reply(&[1])),
        ask(read_request(606, 1), read_reply(&[1])),
        ask(read_request(602, 2), read_reply(&[-700, 1800])),
        ask(read_request(626, 1), read_reply(&[2])),
    ];
    let reading = vec![
        ask(
            read_request(100, 9),
            read_reply(&[600, 0, 0, 0, 0, 0, 0, 0, 5875]),
        ),
        ask(read_request(200, 1), read_reply(&[0])),
        ask(read_request(300, 1), read_reply(&[600])),
        ask(read_request(1061, 1), read_reply(&[0x0003])),
    ];
    let (mut f4, peer) = chamber(config, script(&[connect, reading]));
    f4.connect().await.unwrap();
    let r = f4.read().await.unwrap();
    assert_eq!(r.product_c, Some(58.75));
    assert_eq!(r.alarms, vec!["door open".to_string()]);
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn going_safe_to_ambient_is_confirmed_by_reading_back() {
    let safe = vec![
        ask(read_request(200, 1), read_reply(&[0])),
        ask(write_request(300, 230), write_request(300, 230)),
        ask(read_request(300, 1), read_reply(&[230])),
        ask(read_request(200, 1), read_reply(&[0])),
    ];
    // Not connected yet: going safe connects first (the teardown after a failed start).
    let (mut f4, peer) = chamber(WatlowConfig::default(), script(&[connect_script(), safe]));
    let report = f4.go_safe(SafeState::default()).await;
    assert!(report.confirmed, "{}", report.detail);
    assert!(
        report.detail.contains("setpoint 23 °C read back"),
        "{}",
        report.detail
    );
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn a_silent_chamber_is_not_confirmed_safe_within_a_bounded_time() {
    let s = (0..3).map(|_| silent(read_request(901, 1))).collect();
    let (mut f4, peer) = chamber(WatlowConfig::default(), s);
    let t0 = Instant::now();
    let report = f4.go_safe(SafeState::default()).await;
    assert_eq!(t0.elapsed(), Duration::from_secs(3));
    assert!(!report.confirmed);
    assert!(report.detail.contains("silent"), "{}", report.detail);
    finish(f4, peer).await;
}

#[tokio::test(start_paused = true)]
async fn standby_without_a_chamber_on_output_is_not_guessed() {
    let (mut f4, peer) = chamber(WatlowConfig::default(), vec![]);
    let report = f4.go_safe(SafeState::Standby).await;
    assert!(!report.confirmed);
    assert!(
        report.detail.contains("no standby register"),
        "{}",
        report.detail
    );
    assert!(
        report.detail.contains("chamber_on_output"),
        "{}",
        report.detail
    );
    finish(f4, peer).await; // nothing was sent
}

#[tokio::test(start_paused = true)]
async fn off_through_a_configured_event_output() {
    let config = WatlowConfig {
        chamber_on_output: Some(3),
        ..WatlowConfig::default()
    };
    let (mut f4, peer) = chamber(
        config,
        vec![
            ask(write_request(2020, 0), write_request(2020, 0)),
            ask(read_request(2020, 1), read_reply(&[0])),
        ],
    );
    let report = f4.go_safe(SafeState::Off).await;
    assert!(report.confirmed, "{}", report.detail);
    assert!(
        report.detail.contains("event output 3"),
        "{}",
        report.detail
    );
    finish(f4, peer).await;
}

/// Modbus TCP: the MBAP header (transaction id, protocol 0, length, unit id) and no CRC. The
/// peer answers with the transaction id it was sent.
#[tokio::test(start_paused = true)]
async fn modbus_tcp_frames() {
    let (host, mut device) = tokio::io::duplex(4096);
    let mut f4 = WatlowF4::over_tcp_stream(host, "127.0.0.1:502", WatlowConfig::default()).unwrap();
    let peer = tokio::spawn(async move {
        let mut req = [0u8; 12];
        device.read_exact(&mut req).await.unwrap();
        // protocol 0, length 6, unit 1, function 3, address 901, count 1
        assert_eq!(
            &req[2..],
            &[0, 0, 0, 6, 1, 0x03, 0x03, 0x85, 0, 1],
            "{req:02X?}"
        );
        let reply = [req[0], req[1], 0, 0, 0, 5, 1, 0x03, 2, 0, 0];
        device.write_all(&reply).await.unwrap();
    });
    let e = f4.connect().await.unwrap_err();
    // The unit answered °F (0): refused, which shows the reply was decoded.
    assert_eq!(e.kind(), ChamberErrorKind::Setup);
    assert!(f4.describe().contains("Modbus TCP"));
    peer.await.unwrap();
}

#[test]
fn the_timing_model_counts_the_frames() {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let (host, _device) = tokio::io::duplex(64);
        let f4 = WatlowF4::over_stream(host, "pipe", 9600, WatlowConfig::default()).unwrap();
        let t = f4.timing();
        // Three reads: 9 registers (8 + 23 bytes) and two of one (8 + 7 bytes), each with two
        // 3.5-character gaps, 10 bits a character at 9600 baud, plus 50 ms latency each.
        let chars = (8.0 + 23.0 + 7.0) + 2.0 * (8.0 + 7.0 + 7.0);
        let expected = chars * 10.0 / 9600.0 + 3.0 * 0.050;
        assert!((t.read.as_secs_f64() - expected).abs() < 1e-9, "{t:?}");
        assert_eq!(t.reply_timeout, Duration::from_secs(1));
    });
}
