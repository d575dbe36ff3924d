//! For the tests of `gyrocal serve` and `gyrocal run --serve`: a child process ended with the
//! test, plain HTTP/1.1 requests, the port of a printed URL, and an event stream read in the
//! background.

use std::io::{BufRead as _, BufReader, Read as _, Write as _};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A run id no other test (or earlier run on the same PostgreSQL database) uses.
pub fn uniq(name: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    format!("{name}-{}-{nanos}", std::process::id())
}

/// Two benches' roots and a view's empty working directory (no `runs`), made in `dir`.
pub fn two_benches_and_a_view(dir: &std::path::Path) -> [std::path::PathBuf; 3] {
    let dirs = ["bench-a", "bench-b", "view"].map(|d| dir.join(d));
    for d in &dirs {
        std::fs::create_dir(d).unwrap();
    }
    dirs
}

/// Ends a child process of this test when the test ends, however it ends.
pub struct Reap(pub Child);

impl Drop for Reap {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `serve` (a `gyrocal serve` command with `--port 0`) and reads the URL it prints
/// first: the child (ended with the test), that line, and the port.
pub fn start(mut serve: Command) -> (Reap, String, u16) {
    let mut child = Reap(
        serve
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mut line = String::new();
    BufReader::new(child.0.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let port = port_in(&line);
    (child, line, port)
}

/// `GET path` on `port` (HTTP/1.1, connection closed after): status line and body.
pub fn get(port: u16, path: &str) -> (String, String) {
    try_get(port, path).unwrap_or_else(|| panic!("nothing listens on port {port}"))
}

/// [`get`], or `None` when nothing listens on `port` any more (a server that ended with its
/// run), or the server went away during the exchange (the run ended while it answered: the
/// connection is reset, or closed before a status line).
pub fn try_get(port: u16, path: &str) -> Option<(String, String)> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut text = String::new();
    match s.read_to_string(&mut text) {
        Ok(_) if text.starts_with("HTTP/") => {}
        Ok(_) => return None,
        Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return None,
        Err(e) => panic!("GET {path} on port {port}: {e}"),
    }
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    Some((
        head.lines().next().unwrap_or("").to_string(),
        body.to_string(),
    ))
}

/// The port of the first `http://HOST:PORT` in `line`.
pub fn port_in(line: &str) -> u16 {
    let at = line.find("http://").expect("a URL in the line") + "http://".len();
    let rest = &line[at..];
    let host_port = rest.split('/').next().unwrap();
    host_port
        .rsplit(':')
        .next()
        .unwrap()
        .trim()
        .parse()
        .unwrap()
}

/// The runs of `/api/runs`.
pub fn api_runs(port: u16) -> Vec<serde_json::Value> {
    let (status, body) = get(port, "/api/runs");
    assert!(status.contains("200"), "{status}");
    let doc: serde_json::Value = serde_json::from_str(&body).unwrap();
    doc["runs"].as_array().cloned().unwrap_or_default()
}

/// An `/api/events` stream read by a thread of its own into a text that grows.
pub struct Events(Arc<Mutex<String>>);

impl Events {
    /// Connects to `port`'s event stream (before the test makes anything change).
    pub fn start(port: u16) -> Events {
        let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
        write!(s, "GET /api/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
        let text = Arc::new(Mutex::new(String::new()));
        let sink = text.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 8192];
            while let Ok(n) = s.read(&mut buf) {
                if n == 0 {
                    break;
                }
                sink.lock()
                    .unwrap()
                    .push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        });
        Events(text)
    }

    /// What came so far.
    pub fn text(&self) -> String {
        self.0.lock().unwrap().clone()
    }
}

/// A TCP relay to the test's PostgreSQL that the test can cut (every connection through it
/// shut down, and new ones refused, as a server restarting or a network gone) and restore.
pub struct Relay {
    /// `url` with the relay in place of its host and port.
    pub url: String,
    down: Arc<std::sync::atomic::AtomicBool>,
    conns: Arc<Mutex<Vec<TcpStream>>>,
}

impl Relay {
    /// A relay to the server of `url` (`postgres://USER[:PASS]@HOST:PORT/DB`).
    pub fn to(url: &str) -> Relay {
        use std::sync::atomic::Ordering;
        let at = url.rfind('@').expect("a user in the URL") + 1;
        let slash = at + url[at..].find('/').expect("a database in the URL");
        let target = url[at..slash].to_string();
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let relayed = format!(
            "{}127.0.0.1:{}{}",
            &url[..at],
            l.local_addr().unwrap().port(),
            &url[slash..]
        );
        let down = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let conns = Arc::new(Mutex::new(Vec::new()));
        let (d, c) = (down.clone(), conns.clone());
        std::thread::spawn(move || {
            for client in l.incoming() {
                let Ok(client) = client else { continue };
                if d.load(Ordering::SeqCst) {
                    continue; // dropped: refused
                }
                let Ok(server) = TcpStream::connect(&target) else {
                    continue;
                };
                let mut held = c.lock().unwrap();
                held.push(client.try_clone().unwrap());
                held.push(server.try_clone().unwrap());
                for (mut from, mut to) in [
                    (client.try_clone().unwrap(), server.try_clone().unwrap()),
                    (server, client),
                ] {
                    std::thread::spawn(move || {
                        let _ = std::io::copy(&mut from, &mut to);
                        let _ = to.shutdown(std::net::Shutdown::Both);
                    });
                }
            }
        });
        Relay {
            url: relayed,
            down,
            conns,
        }
    }

    /// Shuts every connection through the relay down and refuses new ones until
    /// [`Relay::restore`].
    pub fn cut(&self) {
        self.down.store(true, std::sync::atomic::Ordering::SeqCst);
        for s in self.conns.lock().unwrap().drain(..) {
            let _ = s.shutdown(std::net::Shutdown::Both);
        }
    }

    /// Passes new connections again.
    pub fn restore(&self) {
        self.down.store(false, std::sync::atomic::Ordering::SeqCst);
    }
}
