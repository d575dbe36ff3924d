//! The Watlow F4 through real links: Modbus RTU on a pseudo-terminal opened as a serial port
//! (8N1, the path a plan names) and Modbus TCP on a loopback socket, each with a scripted
//! controller of this file's own at the other end. Real time (real I/O), no timing asserted.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use gyrocal_chamber::{Chamber, ChamberMode, WatlowConfig, WatlowF4};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

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

/// The registers a controller at 25.0 °C in °C with one decimal holds.
fn register(addr: u16) -> i16 {
    match addr {
        901 => 1,
        606 | 616 => 1,
        602 => -700,
        603 => 1800,
        100 => 251,
        104 => 248,
        200 => 0,
        300 => 250,
        _ => 0,
    }
}

/// A controller answering reads of holding registers, over RTU frames. Returns its end of
/// the link, so that the test closes it only after the driver read the last reply (a
/// pseudo-terminal whose master closes drops what the slave had not read yet).
async fn rtu_controller<T: AsyncRead + AsyncWrite + Unpin>(mut io: T, requests: usize) -> T {
    for _ in 0..requests {
        let mut req = [0u8; 8];
        io.read_exact(&mut req).await.unwrap();
        assert_eq!(crc(&req[..6]), [req[6], req[7]], "request CRC");
        assert_eq!(&req[..2], &[1, 3], "slave 1, read holding registers");
        let addr = u16::from_be_bytes([req[2], req[3]]);
        let count = u16::from_be_bytes([req[4], req[5]]);
        let mut reply = vec![1, 3, (2 * count) as u8];
        for a in addr..addr + count {
            reply.extend_from_slice(&register(a).to_be_bytes());
        }
        let c = crc(&reply);
        reply.extend_from_slice(&c);
        io.write_all(&reply).await.unwrap();
    }
    io
}

#[cfg(unix)]
#[tokio::test]
async fn modbus_rtu_through_a_pseudo_terminal() {
    let (master, placeholder, path) = gyrocal_link::pseudo_terminal().unwrap();
    let controller = tokio::spawn(rtu_controller(master, 7));
    let mut f4 = WatlowF4::open_rtu(&path, 9600, WatlowConfig::default()).unwrap();
    drop(placeholder);
    f4.connect().await.unwrap();
    let r = f4.read().await.unwrap();
    assert_eq!(r.air_c, 25.1);
    assert_eq!(r.product_c, Some(24.8));
    assert_eq!(r.setpoint_c, 25.0);
    assert_eq!(r.mode, ChamberMode::Constant);
    assert!(f4.describe().contains("Modbus RTU 9600 8N1, slave 1"));
    drop(controller.await.unwrap());
}

#[tokio::test]
async fn a_baud_the_f4_does_not_offer_is_refused_before_opening() {
    let e =
        WatlowF4::open_rtu("/dev/does-not-matter", 115_200, WatlowConfig::default()).unwrap_err();
    assert_eq!(e.kind(), gyrocal_chamber::ChamberErrorKind::Setup);
    assert!(e.to_string().contains("baud 115200"), "{e}");
}

#[tokio::test]
async fn a_missing_port_is_a_link_error_naming_it() {
    let e = WatlowF4::open_rtu("/dev/ttyNOPE9", 9600, WatlowConfig::default()).unwrap_err();
    assert_eq!(e.kind(), gyrocal_chamber::ChamberErrorKind::Link);
    assert!(e.to_string().contains("/dev/ttyNOPE9"), "{e}");
}

#[tokio::test]
async fn modbus_tcp_through_a_loopback_socket() {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let controller = tokio::spawn(async move {
        let (mut io, _) = listener.accept().await.unwrap();
        for _ in 0..7 {
            let mut req = [0u8; 12];
            io.read_exact(&mut req).await.unwrap();
            assert_eq!(&req[2..8], &[0, 0, 0, 6, 1, 3], "MBAP, unit 1, function 3");
            let addr = u16::from_be_bytes([req[8], req[9]]);
            let count = u16::from_be_bytes([req[10], req[11]]);
            let len = 3 + 2 * count;
            let [lh, ll] = len.to_be_bytes();
            let mut reply = vec![req[0], req[1], 0, 0, lh, ll, 1, 3, (2 * count) as u8];
            for a in addr..addr + count {
                reply.extend_from_slice(&register(a).to_be_bytes());
            }
            io.write_all(&reply).await.unwrap();
        }
    });
    let mut f4 = WatlowF4::connect_tcp(&addr, WatlowConfig::default())
        .await
        .unwrap();
    f4.connect().await.unwrap();
    let r = f4.read().await.unwrap();
    assert_eq!((r.air_c, r.product_c), (25.1, Some(24.8)));
    controller.await.unwrap();
}

#[tokio::test]
async fn nobody_listening_is_a_link_error() {
    // Bind then drop, so the port is (very likely) closed.
    let addr = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().to_string()
    };
    let e = WatlowF4::connect_tcp(&addr, WatlowConfig::default())
        .await
        .unwrap_err();
    assert_eq!(e.kind(), gyrocal_chamber::ChamberErrorKind::Link);
    assert!(e.to_string().contains(&addr), "{e}");
}
