//! The server's connection limits on a real socket: past [`MAX_CONNECTIONS`] a connection
//! waits (queued in the backlog, never refused) and is answered once a slot frees; a client
//! that says nothing, or drips its request head, is closed at the head deadline and gives its
//! slot back, and so is one that drips the head of its second request on a kept-alive
//! connection, or sends none; a listening event stream stays past the idle deadline (its
//! keep-alive); header sets above the limit are refused.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test helpers: a panic is a failed test

use std::io::{Read as _, Write as _};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use gyrocal_serve::limits::Limited;
use gyrocal_serve::{App, HEADER_TIMEOUT, MAX_CONNECTIONS, ServeConfig};

/// A server on a free port with `limited`'s limits, on a runtime of its own.
fn start(limits: impl FnOnce(tokio::net::TcpListener) -> Limited + Send + 'static) -> u16 {
    let root = tempfile::tempdir().unwrap().keep();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            tx.send(l.local_addr().unwrap().port()).unwrap();
            let app = App::new(ServeConfig {
                roots: vec![root],
                ..ServeConfig::default()
            });
            let _ = app.serve_limited(limits(l)).await;
        });
    });
    rx.recv().unwrap()
}

/// Sends `GET path` on `s` and reads the answer's status line (None: closed or no answer
/// within the stream's read timeout).
fn ask(s: &mut TcpStream, path: &str) -> Option<String> {
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut text = String::new();
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => text.push_str(&String::from_utf8_lossy(&buf[..n])),
            Err(_) if text.is_empty() => return None,
            Err(_) => break,
        }
    }
    text.lines().next().map(str::to_string)
}

#[test]
fn past_the_connection_limit_a_client_waits_and_is_answered_once_the_silent_ones_are_closed() {
    let port = start(Limited::new);
    // every slot taken by clients that connect and say nothing
    let silent: Vec<TcpStream> = (0..MAX_CONNECTIONS)
        .map(|_| TcpStream::connect(("127.0.0.1", port)).unwrap())
        .collect();
    // give the server time to accept them all
    std::thread::sleep(Duration::from_millis(500));
    let t0 = Instant::now();
    let mut next = TcpStream::connect(("127.0.0.1", port)).expect("queued, not refused");
    next.set_read_timeout(Some(Duration::from_secs(1))).unwrap();
    assert_eq!(
        ask(&mut next, "/api/runs"),
        None,
        "answered while every slot was held"
    );
    // the silent ones are closed at the head deadline; the waiting one is then answered
    next.set_read_timeout(Some(HEADER_TIMEOUT * 6)).unwrap();
    let mut rest = String::new();
    let mut buf = [0u8; 4096];
    while !rest.contains("\r\n\r\n") {
        let n = next.read(&mut buf).unwrap();
        assert!(n > 0, "closed without an answer after {:?}", t0.elapsed());
        rest.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    assert!(rest.starts_with("HTTP/1.1 200"), "{rest}");
    // and the silent ones were closed by the server
    let mut closed = 0;
    for mut s in silent {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        if matches!(s.read(&mut buf), Ok(0) | Err(_)) {
            closed += 1;
        }
    }
    assert_eq!(closed, MAX_CONNECTIONS);
}

#[test]
fn a_dripping_client_is_closed_at_the_head_deadline_and_gives_its_slot_back() {
    let port = start(|l| Limited::with(l, 1, Duration::from_millis(800), Duration::from_secs(3)));
    let mut drip = TcpStream::connect(("127.0.0.1", port)).unwrap();
    drip.set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    let t0 = Instant::now();
    let mut closed = false;
    for b in b"GET /api/runs HTTP/1.1\r\nHost: x\r\nX-Slow: "
        .iter()
        .cycle()
        .take(200)
    {
        if drip.write_all(&[*b]).is_err() {
            closed = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
        if t0.elapsed() > Duration::from_secs(20) {
            break;
        }
    }
    if !closed {
        let mut buf = [0u8; 256];
        closed = matches!(drip.read(&mut buf), Ok(0) | Err(_));
    }
    assert!(closed, "the dripping client kept its connection");
    // the one slot is free again
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let status = ask(&mut s, "/api/runs").expect("answered");
    assert!(status.contains("200"), "{status}");
}

/// Reads one answer on a kept-alive connection (its head, then `Content-Length` bytes): its
/// status line.
fn read_answer(s: &mut TcpStream) -> String {
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    let head_end = loop {
        if let Some(i) = got.windows(4).position(|w| w == b"\r\n\r\n") {
            break i + 4;
        }
        let n = s.read(&mut buf).unwrap();
        assert!(n > 0, "closed before the answer");
        got.extend_from_slice(&buf[..n]);
    };
    let head = String::from_utf8_lossy(&got[..head_end]).to_string();
    let len: usize = head
        .lines()
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            k.eq_ignore_ascii_case("content-length")
                .then(|| v.trim().parse().unwrap())
        })
        .expect("a Content-Length");
    while got.len() < head_end + len {
        let n = s.read(&mut buf).unwrap();
        assert!(n > 0, "closed in the answer's body");
        got.extend_from_slice(&buf[..n]);
    }
    head.lines().next().unwrap().to_string()
}

/// True when the server closed `s` (a write fails, or a read finds the end).
fn closed_by_server(s: &mut TcpStream) -> bool {
    let mut buf = [0u8; 256];
    matches!(s.read(&mut buf), Ok(0) | Err(_))
}

#[test]
fn on_a_kept_alive_connection_the_next_head_has_the_same_deadline_as_the_first() {
    // head deadline 2 s, idle deadline 60 s: only the head deadline can close these
    let head = Duration::from_secs(2);
    let port = start(move |l| Limited::with(l, 2, head, Duration::from_secs(60)));

    // one full request answered, then the next head dripped a byte every 50 ms
    let mut drip = TcpStream::connect(("127.0.0.1", port)).unwrap();
    drip.set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    write!(drip, "GET /api/runs HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    assert!(read_answer(&mut drip).contains("200"));
    let t0 = Instant::now();
    let mut closed = false;
    for b in b"GET /api/runs HTTP/1.1\r\nHost: x\r\nX-Slow: "
        .iter()
        .cycle()
        .take(400)
    {
        if drip.write_all(&[*b]).is_err() {
            closed = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
        if t0.elapsed() > Duration::from_secs(20) {
            break;
        }
    }
    // a write may still succeed after the server closed (the kernel's buffer): read too
    closed = closed || closed_by_server(&mut drip);
    assert!(
        closed,
        "the second head was dripped for {:?} and the connection stayed",
        t0.elapsed()
    );
    assert!(t0.elapsed() >= head / 2, "closed before the deadline");

    // one request answered, then nothing: closed at the head deadline, not the idle one
    let mut quiet = TcpStream::connect(("127.0.0.1", port)).unwrap();
    quiet
        .set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    write!(quiet, "GET /api/runs HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    assert!(read_answer(&mut quiet).contains("200"));
    let t0 = Instant::now();
    assert!(closed_by_server(&mut quiet), "still open");
    assert!(
        t0.elapsed() < Duration::from_secs(30),
        "closed only after {:?}",
        t0.elapsed()
    );
    // a second request in time on a kept-alive connection is answered as the first
    let mut keep = TcpStream::connect(("127.0.0.1", port)).unwrap();
    keep.set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    for _ in 0..2 {
        write!(keep, "GET /api/runs HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        assert!(read_answer(&mut keep).contains("200"));
    }
}

#[test]
fn an_event_stream_outlives_the_idle_deadline_and_huge_headers_are_refused() {
    // idle deadline shorter than the stream's 15 s keep-alive would close it: 20 s here
    let port = start(|l| Limited::with(l, 8, Duration::from_secs(5), Duration::from_secs(20)));
    let mut es = TcpStream::connect(("127.0.0.1", port)).unwrap();
    es.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    write!(es, "GET /api/events HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    let mut got = String::new();
    let mut buf = [0u8; 4096];
    // the head, then a keep-alive comment after about 15 s: the stream is still open
    let t0 = Instant::now();
    while !got.contains("\n:") {
        let n = es.read(&mut buf).unwrap();
        assert!(n > 0, "the stream closed after {:?}: {got}", t0.elapsed());
        got.push_str(&String::from_utf8_lossy(&buf[..n]));
    }
    assert!(got.contains("text/event-stream"), "{got}");

    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let big = "a".repeat(4000);
    let mut req = String::from("GET /api/runs HTTP/1.1\r\nHost: x\r\nConnection: close\r\n");
    for i in 0..8 {
        req.push_str(&format!("X-Big-{i}: {big}\r\n"));
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).unwrap();
    let mut text = String::new();
    let _ = s.read_to_string(&mut text);
    assert!(
        text.starts_with("HTTP/1.1 431"),
        "{}",
        text.lines().next().unwrap_or("")
    );
}
